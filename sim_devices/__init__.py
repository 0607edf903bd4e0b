"""Simulated venues and devices: ground truth and raw sensor streams with documented error models."""
