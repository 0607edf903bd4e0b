"""A swimmer's sensors (waist, back, head, a kickboard): attitude and rows, walls, our per-length estimate, and the
paper's (`paper.py`)."""
