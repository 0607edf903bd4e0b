"""The venue hub's core, no I/O: every agent's messages in, corrections (collisions, beacons, fixes), map matching
and camera identities out; `venue.py` joins the parts (the process around it: reckon/processes/hub.py)."""
