"""Simulated devices: x-IMU3 and TSND121/151 bytes, on real pseudo-terminals."""
