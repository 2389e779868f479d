"""What the workflow needs to run jobs: their code inputs, memory and disk estimates, the
live-run lock of a study folder, and the report's captions."""
