"""`reckon bench`: pipeline speed and latency, hub load, soak (docs/benchmarks.md)."""
