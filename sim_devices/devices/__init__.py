"""Simulated devices: x-IMU3 and TSND121/151 bytes on real pseudo-terminals (`pty` is their base),
and the IMU error model (`imu`) and device clock (`clock`) every simulated venue uses."""
