"""The solvers users call: checked inputs, one sample at a time (continuation and Newton,
warm-started) or N on arrays, joint poses, forward dynamics, and InverseDynamics on top.
"""
