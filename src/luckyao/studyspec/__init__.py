"""The study configuration: its schema, validation and defaults, sweeps, size scaling, the
resolved case and the specs (and keys) of the cached products."""
