"""The hub's part for wheelchairs: clock offsets, collisions, beacon passes, fixes, the fixed-lag smoother; the paper's rules in `paper.py`."""
