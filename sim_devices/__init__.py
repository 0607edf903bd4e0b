"""Simulated venues (a package per kind: wheelchair/, swim/, room/, pedestrian/, camera/) and
simulated devices (devices/): ground truth and raw sensor streams with documented error models."""
