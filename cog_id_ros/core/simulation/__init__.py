"""Simulation: the equation of motion integrated in time (RK4 on the independent coordinates,
the loops closed at every stage), with an error estimate per step.
"""
