"""What users call: InverseDynamics, the solver of actuator space (solve/) that also takes a
motion in joint space (transmission/)."""
