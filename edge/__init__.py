"""Per-device edge: a package per agent kind (chair/, swim/, pedestrian/) of constant-memory
dead-reckoning cores with no I/O, the decoders that turn device bytes into samples (decoders/),
and the sources that read devices, one module per URL scheme (sources/, the only I/O here)."""
