"""Loop closure: the constraint equations of the closed loops and their Jacobian, Newton's
method and continuation on them, and the map from the actuators' rates to every joint's
rates (the constraint's null space).
"""
