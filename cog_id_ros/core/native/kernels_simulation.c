/* One Simulation substep in C: cog_id_ros/core/simulation.py's RK4 over the kernels above
   (body_prediction, body_closure, body_forward), for the case the Python step takes most
   often: every stage one continuation step from the substep's start, closed by Newton, not
   singular; and its error estimate and branch check (simulation_error.py's step_error).
   The same operations in the same order as the Python step, so the same numbers; anything
   else (a stage that needs continuation, a failure to report) returns None and the Python
   step does it. Emitted by cog_id_ros.core.native_simulation (SIM_* defined there): do not
   edit a generated copy. */

#include <float.h>

/* the stage record: every field of the forward kernel's record */
typedef struct {
    double q[SIM_N];            /* the closed pose */
    double basis[SIM_N * SIM_DOF];
    double rec[SIM_FORWARD_WIDTH];
} sim_pose;

/* V_a zd: the active joints' rates of the primary rates zd (the Python sum's order) */
static void sim_active_rates(const double *basis, const double *zd, double *rates)
{
    for (int a = 0; a < SIM_M; a++) {
        const double *row = basis + sim_active[a] * SIM_DOF;
        double s = 0.0;
        for (int k = 0; k < SIM_DOF; k++)
            s = k ? s + row[k] * zd[k] : row[k] * zd[k];
        rates[a] = s;
    }
}

/* the forward record is usable: inertia not singular, accelerations finite */
static int sim_checked(const double *rec, const double *cfg)
{
    if (!(rec[SIM_OFF_INERTIA] <= cfg[2]))
        return 0;
    for (int a = 0; a < SIM_M; a++)
        if (!isfinite(rec[SIM_OFF_ACC + a]))
            return 0;
    return 1;
}

/* Newton's method on the loop equations from p->q (SampleSolver.close); 1 when closed, and
   then p->rec the forward record there */
static int sim_close(sim_pose *p, const double *target, const double *qd, const double *tau,
                     const double *cfg)
{
    double crec[SIM_CLOSURE_WIDTH];
    int whole = 0;
    body_closure(p->q, crec);
    for (int it = 0; it <= SIM_NEWTON_ITERATIONS; it++) {
        const double *r = whole ? p->rec : crec;
        if (r[SIM_OFF_WORST] < cfg[0] && r[SIM_OFF_LEAST] > 0.0) {
            if (!whole)
                body_forward(p->q, target, qd, tau, p->rec);
            return 1;
        }
        if (it == SIM_NEWTON_ITERATIONS)
            return 0;
        double size = r[SIM_OFF_LARGEST];
        if (!(size < INFINITY))
            return 0;
        if (size < SIM_STAGNATION) {
            double largest = 0.0;
            for (int k = 0; k < SIM_FREE; k++) {
                double x = fabs(p->q[sim_free[k]]);
                if (k == 0 || x > largest)
                    largest = x;
            }
            if (size < 1e-15 * (1.0 + largest))
                return 0;
        }
        double ratio = SIM_NEWTON_MAX_INCREMENT / size;
        double factor = ratio < 1.0 ? ratio : 1.0;
        for (int k = 0; k < SIM_FREE; k++)
            p->q[sim_free[k]] = p->q[sim_free[k]] - r[SIM_OFF_INC + k] * factor;
        whole = size * factor < SIM_LIKELY_CLOSED;
        if (whole)
            body_forward(p->q, target, qd, tau, p->rec);
        else
            body_closure(p->q, crec);
    }
    return 0;
}

/* one stage: the pose with the primary actuators at z, closed from the start pose (q0,
   basis0), and forward dynamics there with the rates V_a zd; 1 when done as the Python
   step's one-step path does it, 0 to leave it to the Python step */
static int sim_stage(const double *q0, const double *basis0, const double *z,
                     const double *zd, const double *tau, const double *cfg, sim_pose *p)
{
    const double *limits = cfg + 3, *bounds = cfg + 3 + SIM_N;
    double target[SIM_M], qd[SIM_M], predicted[2 * SIM_N];
    for (int a = 0; a < SIM_M; a++)
        target[a] = q0[sim_active[a]];
    for (int k = 0; k < SIM_DOF; k++)
        target[sim_primary_active[k]] = z[k];
    for (int w = 0; w < SIM_WRAPPING; w++) {       /* no whole turn to take off */
        int a = sim_wrapping[w];
        if (!(fabs((target[a] - q0[sim_active[a]]) / SIM_TWO_PI) < 0.5))
            return 0;
    }
#if SIM_REDUNDANT
    sim_active_rates(basis0, zd, qd);
#else
    for (int k = 0; k < SIM_DOF; k++)
        qd[sim_primary_active[k]] = zd[k];
#endif
    body_prediction(q0, basis0, target, predicted);
    for (int k = 0; k < SIM_DOF; k++) {              /* fits_one_step */
        int j = sim_primary_joint[k];
        if (!(fabs(target[sim_primary_active[k]] - q0[j]) <= limits[j]))
            return 0;
    }
    for (int j = 0; j < SIM_N; j++)
        if (!(fabs(predicted[SIM_N + j]) <= limits[j]))
            return 0;
    memcpy(p->q, predicted, sizeof(p->q));
    if (!sim_close(p, target, qd, tau, cfg) || !(p->rec[SIM_OFF_COND] <= cfg[1]))
        return 0;
    for (int j = 0; j < SIM_N; j++)                 /* correction_ok */
        if (!(fabs(p->q[j] - predicted[j]) <= bounds[j]))
            return 0;
    memset(p->basis, 0, sizeof(p->basis));
    for (int k = 0; k < SIM_DOF; k++)
        p->basis[sim_primary_joint[k] * SIM_DOF + k] = 1.0;
    for (int f = 0; f < SIM_FREE; f++)
        memcpy(p->basis + sim_free[f] * SIM_DOF, p->rec + SIM_OFF_BASIS + f * SIM_DOF,
               SIM_DOF * sizeof(double));
    if (!sim_checked(p->rec, cfg))
        return 0;
#if SIM_REDUNDANT
    for (int a = 0; a < SIM_M; a++)
        target[a] = p->q[sim_active[a]];
    sim_active_rates(p->basis, zd, qd);
    body_forward(p->q, target, qd, tau, p->rec);
    if (!sim_checked(p->rec, cfg))
        return 0;
#endif
    return 1;
}

/* the larger of x and acc, NaN once NaN (simulation_error._larger) */
static double sim_larger(double x, double acc)
{
    return (x > acc || x != x) ? x : acc;
}

/* row . v over the primary actuators, the first product first (simulation_error._dot) */
static double sim_dot(const double *row, const double *v)
{
    double s = row[0] * v[0];
    for (int k = 1; k < SIM_DOF; k++)
        s = s + row[k] * v[k];
    return s;
}

/* simulation_error.step_error, its operations in its order: out = (error estimate, branch
   mismatch, motion, speed) of the substep of length h from (q0, basis0, zd) to (p,
   zd_new); zd4, k4 the fourth stage's rates and accelerations; scales, floor_: the joints'
   units */
static void sim_error(double h, const double *q0, const double *basis0, const double *zd,
                      const sim_pose *p, const double *zd_new, const double *zd4,
                      const double *k4, const double *scales, double floor_, double *out)
{
    const double sixth = h / 6.0, half = 0.5 * h;
    double dz[SIM_DOF], dv[SIM_DOF];
    for (int k = 0; k < SIM_DOF; k++) {
        dz[k] = sixth * (zd4[k] - zd_new[k]);
        dv[k] = sixth * (k4[k] - p->rec[SIM_OFF_ACC + sim_primary_active[k]]);
    }
    double position = 0.0, velocity = 0.0, speed = 0.0, mismatch = 0.0, motion = 0.0;
    for (int j = 0; j < SIM_N; j++) {
        const double *row0 = basis0 + j * SIM_DOF, *row1 = p->basis + j * SIM_DOF;
        const double u = scales[j];
        double r0 = sim_dot(row0, zd), r1 = sim_dot(row1, zd_new);
        position = sim_larger(fabs(sim_dot(row1, dz)) * u, position);
        velocity = sim_larger(fabs(sim_dot(row1, dv)) * u, velocity);
        speed = sim_larger(fabs(r0) * u, speed);
        speed = sim_larger(fabs(r1) * u, speed);
        double d = p->q[j] - q0[j];
        motion = sim_larger(fabs(d) * u, motion);
        mismatch = sim_larger(fabs(d - half * (r0 + r1)) * u, mismatch);
    }
    out[0] = sim_larger(velocity / (speed + floor_), position);
    out[1] = mismatch;
    out[2] = motion;
    out[3] = speed;
}

/* the largest rounding measure of the evaluations so far (simulation_error.rounding):
   (s + eps) kappa^2 + eps kappa_H, s the Newton increment left at the pose */
static double sim_rounding(const double *rec, double largest)
{
    const double kappa = rec[SIM_OFF_COND];
    return sim_larger((rec[SIM_OFF_LARGEST] + DBL_EPSILON) * kappa * kappa +
                      DBL_EPSILON * rec[SIM_OFF_INERTIA], largest);
}

/* rk4_step(q, basis, zd, tau, k1, cfg): one substep (simulation.py), or None where the
   Python step must do it. k1: the primary accelerations at the start with these efforts, or
   None. cfg: [substep, closure tolerance, max condition number, inertia limit, joint step
   limits (n), correction bounds (n), unit scales (n), speed floor] (native_simulation's
   step_config). Returns the fields of
   simulation_error.Substep: (q, basis rows, zd, accelerations, worst, condition, inertia
   condition, error estimate, branch mismatch, motion, speed, the largest rounding measure
   (sim_rounding) of the evaluations at its ends (k1 when evaluated, k4, k5) and between
   them (k2, k3), its largest primary acceleration in joint units). */
static PyObject *sim_rk4_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double q0[SIM_N], basis0[SIM_N * SIM_DOF], zd[SIM_DOF], tau[SIM_M], k[5][SIM_DOF];
    double cfg[5 + 3 * SIM_N], error[4], ends = 0.0, inside = 0.0, scale = 0.0;
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "rk4_step() takes 6 arguments");
        return NULL;
    }
    if (read_doubles(args[0], q0, SIM_N, "q") < 0 ||
            read_rows(args[1], basis0, SIM_N, SIM_DOF, "basis") < 0 ||
            read_doubles(args[2], zd, SIM_DOF, "zd") < 0 ||
            read_doubles(args[3], tau, SIM_M, "tau") < 0 ||
            read_doubles(args[5], cfg, 5 + 3 * SIM_N, "cfg") < 0)
        return NULL;
    const double h = cfg[0], *stage_cfg = cfg + 1, *scales = cfg + 4 + 2 * SIM_N;
    sim_pose p;
    double z[SIM_DOF], zs[SIM_DOF], zds[4][SIM_DOF];
    for (int i = 0; i < SIM_DOF; i++)
        z[i] = q0[sim_primary_joint[i]];
    if (args[4] != Py_None) {
        if (read_doubles(args[4], k[0], SIM_DOF, "k1") < 0)
            return NULL;
    } else {
        double target[SIM_M], rates[SIM_M];
        for (int a = 0; a < SIM_M; a++)
            target[a] = q0[sim_active[a]];
        sim_active_rates(basis0, zd, rates);
        body_forward(q0, target, rates, tau, p.rec);
        if (!sim_checked(p.rec, stage_cfg))
            Py_RETURN_NONE;
        ends = sim_rounding(p.rec, ends);
        for (int i = 0; i < SIM_DOF; i++)
            k[0][i] = p.rec[SIM_OFF_ACC + sim_primary_active[i]];
    }
    const double half = 0.5 * h;
    memcpy(zds[0], zd, sizeof(zd));
    for (int s = 1; s < 4; s++) {     /* stages 2, 3, 4: at h/2, h/2, h */
        double dt = s < 3 ? half : h;
        for (int i = 0; i < SIM_DOF; i++) {
            zds[s][i] = s < 3 ? zd[i] + 0.5 * h * k[s - 1][i] : zd[i] + h * k[s - 1][i];
            zs[i] = z[i] + dt * zds[s - 1][i];
        }
        if (!sim_stage(q0, basis0, zs, zds[s], tau, stage_cfg, &p))
            Py_RETURN_NONE;
        if (s < 3)
            inside = sim_rounding(p.rec, inside);
        else
            ends = sim_rounding(p.rec, ends);
        for (int i = 0; i < SIM_DOF; i++)
            k[s][i] = p.rec[SIM_OFF_ACC + sim_primary_active[i]];
    }
    const double sixth = h / 6.0;
    double zd_new[SIM_DOF];
    for (int i = 0; i < SIM_DOF; i++) {
        zs[i] = z[i] + sixth * (zds[0][i] + 2.0 * zds[1][i] + 2.0 * zds[2][i] + zds[3][i]);
        zd_new[i] = zd[i] + sixth * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i]);
    }
    if (!sim_stage(q0, basis0, zs, zd_new, tau, stage_cfg, &p))
        Py_RETURN_NONE;
    ends = sim_rounding(p.rec, ends);
    for (int i = 0; i < SIM_DOF; i++)
        k[4][i] = p.rec[SIM_OFF_ACC + sim_primary_active[i]];
    for (int s = 0; s < 5; s++)        /* simulation_error.acceleration_scale */
        for (int i = 0; i < SIM_DOF; i++)
            scale = sim_larger(fabs(k[s][i]) * scales[sim_primary_joint[i]], scale);
    sim_error(h, q0, basis0, zd, &p, zd_new, zds[3], k[3], scales, cfg[4 + 3 * SIM_N], error);
    double numbers[10] = {p.rec[SIM_OFF_WORST], p.rec[SIM_OFF_COND], p.rec[SIM_OFF_INERTIA],
                          error[0], error[1], error[2], error[3], ends, inside, scale};
    PyObject *tuple = PyTuple_New(14);
    if (tuple == NULL)
        return NULL;
    PyObject *items[4] = {floats(p.q, SIM_N), rows(p.basis, SIM_N, SIM_DOF),
                          floats(zd_new, SIM_DOF), floats(p.rec + SIM_OFF_ACC, SIM_M)};
    for (int i = 0; i < 14; i++) {
        PyObject *item = i < 4 ? items[i] : PyFloat_FromDouble(numbers[i - 4]);
        if (item == NULL) {
            for (int j = i + 1; j < 4; j++)
                Py_XDECREF(items[j]);
            Py_DECREF(tuple);
            return NULL;
        }
        PyTuple_SET_ITEM(tuple, i, item);     /* (steals the reference) */
    }
    return tuple;
}
