/* One Simulation step in C: cog_id_ros/core/simulation.py's RK4 over the kernels above
   (body_prediction, body_closure, body_forward), for the case the Python step takes most
   often: every stage one continuation step from the step's start, closed by Newton, not
   singular. The same operations in the same order as the Python step, so the same numbers;
   anything else (a stage that needs continuation, a failure to report) returns None and
   the Python step does it. Emitted by cog_id_ros.core.native_simulation (SIM_* defined
   there): do not edit a generated copy. */

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

/* rk4_step(q, basis, zd, tau, k1, cfg): one step (simulation.py), or None where the Python
   step must do it. k1: the primary accelerations at the start with these efforts, or None.
   cfg: [time step, closure tolerance, max condition number, inertia limit, joint step
   limits (n), correction bounds (n)]. Returns (q, basis rows, zd, accelerations, worst). */
static PyObject *sim_rk4_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double q0[SIM_N], basis0[SIM_N * SIM_DOF], zd[SIM_DOF], tau[SIM_M], k[4][SIM_DOF];
    double cfg[4 + 2 * SIM_N];
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "rk4_step() takes 6 arguments");
        return NULL;
    }
    if (read_doubles(args[0], q0, SIM_N, "q") < 0 ||
            read_rows(args[1], basis0, SIM_N, SIM_DOF, "basis") < 0 ||
            read_doubles(args[2], zd, SIM_DOF, "zd") < 0 ||
            read_doubles(args[3], tau, SIM_M, "tau") < 0 ||
            read_doubles(args[5], cfg, 4 + 2 * SIM_N, "cfg") < 0)
        return NULL;
    const double h = cfg[0], *stage_cfg = cfg + 1;
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
    PyObject *out[5] = {floats(p.q, SIM_N), rows(p.basis, SIM_N, SIM_DOF),
                        floats(zd_new, SIM_DOF), floats(p.rec + SIM_OFF_ACC, SIM_M),
                        PyFloat_FromDouble(p.rec[SIM_OFF_WORST])};
    for (int i = 0; i < 5; i++)
        if (out[i] == NULL) {
            for (int j = 0; j < 5; j++)
                Py_XDECREF(out[j]);
            return NULL;
        }
    return Py_BuildValue("(NNNNN)", out[0], out[1], out[2], out[3], out[4]);
}
