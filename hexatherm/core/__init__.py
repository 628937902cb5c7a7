"""Core mathematics: geometry, fitting, registration, kinematics, thermal method.

Nothing in this package reads or writes files or talks to the user: plain numpy
arrays in, typed results out.
"""
