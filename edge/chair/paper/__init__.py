"""The wheelchair paper's method (Hasegawa et al.), our baseline: wheel travel, heading from the magnetometer, impacts, dead reckoning."""
