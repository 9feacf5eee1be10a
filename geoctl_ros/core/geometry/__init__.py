"""Geometry on SO(3) and the sphere: rotations and quaternions, points and paths on the sphere, and
the batch reductions every layer above uses.
"""
