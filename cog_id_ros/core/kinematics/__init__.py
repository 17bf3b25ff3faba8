"""The kinematic tree: joints and their kinds, forward kinematics (poses, twists, bias
accelerations of every link), the parameters a mechanism is read from, and the joints as
written read back from the solver's coordinates.
"""
