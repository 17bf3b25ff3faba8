"""Dynamics of the closed chain: per-link COG Jacobians, Newton-Euler link forces, the inverse
dynamics and the equation of motion H qddot + B = tau, and forward dynamics.
"""
