"""The hub's part for pedestrians: map matching over the walkable area; the paper's turn snap in `paper.py`."""
