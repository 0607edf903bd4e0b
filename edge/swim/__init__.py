"""A swimmer's waist sensor: attitude and rows, walls, our per-length estimate, and the paper's (`paper.py`)."""
