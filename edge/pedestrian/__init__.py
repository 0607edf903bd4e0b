"""A pedestrian's phone: steps, walking direction, the magnetometer aid, our dead reckoning, and the paper's (`paper.py`)."""
