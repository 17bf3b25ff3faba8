"""Newton's method on the loop equations: the constants of its iteration (sample_solve.py
runs it one sample at a time, batch.py on many, kernels_simulation.c inside a Simulation
step: the same rules everywhere)."""

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
