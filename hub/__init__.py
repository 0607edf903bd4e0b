"""Venue hub: subscribes to every agent and corrects drift (collisions, beacons, fixes)."""
