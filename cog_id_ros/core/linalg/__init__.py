"""Spatial algebra and lanes: 3-vectors, rotations, 6-D twists and wrenches, small dense
solves, written once for a float (one sample) and for an (N,) array (N samples).
"""
