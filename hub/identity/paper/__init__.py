"""The camera-identity paper's method (Kawai et al.), our baseline: fragments, features, routes, every permutation."""
