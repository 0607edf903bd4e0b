"""A wheelchair's edge: three IMUs merged, our filter (readable and compiled), and the paper's method in `paper/`."""
