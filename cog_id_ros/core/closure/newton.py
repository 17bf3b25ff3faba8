"""Newton's method on the loop equations: the constants of its iteration (sample_solve.py
runs it one sample at a time, batch.py on many, kernels_simulation.c inside a Simulation
step: the same rules everywhere; the closing past the tolerance where the conditioning needs
it, the last two constants, is InverseDynamics' alone: a Simulation's stages close to the
tolerance)."""

#: Newton iterations of one continuation step (from a first-order prediction within the
#: step limits Newton converges in a few; more means the step is too long: it is halved)
NEWTON_ITERATIONS = 12

#: largest Newton increment (rad or m) applied at once; longer ones are scaled down
NEWTON_MAX_INCREMENT = 0.5

#: after a Newton increment below this (rad or m) the loops are probably closed (Newton
#: converges quadratically: the next residual is of the order of its square times the
#: mechanism's curvature, below the closure tolerance at control rate), so the whole record
#: is evaluated at once; after a larger one (a continuation step far from the pose, a batch
#: anchor) only the closure kernel, until the increments get small
LIKELY_CLOSED = 1e-4

#: a Newton increment below this (rad or m) is checked for stagnation: below 1e-15 of the
#: largest coordinate Newton moves (a larger one cannot be, for coordinates within
#: MAX_ANGLE or lengths; the actuators, held, may be at any angle)
STAGNATION = 1e-5

#: past the closure tolerance, a pose is closed further where its conditioning needs it.
#: The torques' error relative to their scale is about s kappa^2, s the Newton increment
#: left at the pose (rad or m) and kappa the closure Jacobian's condition number (observed:
#: 4e-4 to 0.24 times that over falls of every example into singular poses, the scale being
#: |H qdd| + |B| plus the mechanism's weight times its length scale; docs/api.md). The
#: per-sample and batch paths take one more Newton increment (evaluating the pose again)
#: while s kappa^2 > ACCURACY_FACTOR * closure_tolerance (1e-5 at the default 1e-10):
#: never at a well-conditioned pose closed to the tolerance (kappa below about 300; the
#: examples' motions stay below 70), one or two evaluations more near a singular pose
ACCURACY_FACTOR = 1e5

#: at most this many increments past the tolerance: from a pose closed to it Newton's
#: quadratic convergence reaches rounding in one, and an increment that no longer shrinks
#: ends them (rounding: the pose cannot be closed further; the result says so)
REFINE_ITERATIONS = 3
