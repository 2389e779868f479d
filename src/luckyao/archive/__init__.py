"""A finished study packed with its code, config and environment, and verified by rerunning."""
