"""The mechanism: the closed-chain model made from its parameters and checked at load
(assembled pose, degrees of freedom, idle spins), as Pinocchio's Model is the robot.
"""
