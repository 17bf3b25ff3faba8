"""Kernels and their backends: the lane code traced into a straight-line program, emitted as
Python or C, compiled, cached and loaded.
"""
