"""Per-device edge: decoders and constant-memory dead-reckoning cores (no I/O in the cores)."""
