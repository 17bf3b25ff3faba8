"""Eq. (1)-(4) against finite differences, eq. (7) against energy, on assorted mechanisms."""
import mechanisms as mech
import numpy as np
import pytest

import cog_id_ros


def _paper(t):
    return np.pi / 2 + 0.5 * np.sin(np.pi * t)


CASES = {
    'paper_a': (lambda: mech.from_yaml('config/paper_four_bar_a.yaml'), lambda t: [_paper(t)]),
    'paper_b': (lambda: mech.from_yaml('config/paper_four_bar_b.yaml'), lambda t: [_paper(t), _paper(t)]),
    'crank_rocker': (lambda: mech.four_bar(ground=0.6, crank=0.2, coupler=0.6, rocker=0.4,
                                           active=('joint1',), init=[1.0, -0.6127, 1.4111, 1.0238]),
                     lambda t: [0.9 + 2.0 * t + 0.3 * np.sin(3 * t)]),
    'rocker_driven_on_loop_joint': (
        lambda: mech.four_bar(ground=0.6, crank=0.2, coupler=0.6, rocker=0.4, active=('joint4',),
                              init=[1.0, -0.6127, 1.4111, 1.0238]),
        lambda t: [0.98 + 0.2 * np.sin(2 * t)]),
    'slider_crank': (mech.slider_crank, lambda t: [0.3 + 4.0 * t + 0.5 * np.sin(2 * t)]),
    'double_pendulum': (mech.double_pendulum,
                        lambda t: [0.1 + 0.3 * np.sin(t), 0.5 * np.cos(1.3 * t)]),
}


def trajectory(law, t, h=1e-6):
    """q, qd, qdd of law(t) (central differences of an analytic law: exact to ~1e-8)."""
    q = np.array(law(t)).T
    qd = (np.array(law(t + h)).T - np.array(law(t - h)).T) / (2 * h)
    h2 = 1e-4
    qdd = (np.array(law(t + h2)).T - 2 * q + np.array(law(t - h2)).T) / h2 ** 2
    return q, qd, qdd


def rotation_vector(r):
    """Axis-angle vector of a small rotation matrix (for angular finite differences)."""
    skew = 0.5 * (r - np.swapaxes(r, -1, -2))
    return np.stack([skew[..., 2, 1], skew[..., 0, 2], skew[..., 1, 0]], axis=-1)


@pytest.fixture(params=sorted(CASES))
def case(request):
    params, law = CASES[request.param]
    return cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params())), law


def test_cog_jacobian_is_the_derivative_of_the_cog_pose(case):
    """G_i thetadot = d g_i / dt along a trajectory (eq. 2, 3)."""
    s, law = case
    t = np.linspace(0.0, 1.0, 21)
    q, qd, _ = trajectory(law, t)
    h = 1e-5     # positions are exact to the closure tolerance (1e-10): keep h well above it
    p_plus, r_plus = s.cog_poses(np.array(law(t + h)).T)
    p_minus, r_minus = s.cog_poses(np.array(law(t - h)).T)
    v_fd = (p_plus - p_minus) / (2 * h)
    w_fd = rotation_vector(r_plus @ np.swapaxes(r_minus, -1, -2)) / (2 * h)
    g = s.cog_jacobians(q)
    moved = np.einsum('nlrm,nm->nlr', g, qd)
    scale = 1.0 + np.max(np.abs(moved))
    assert np.max(np.abs(moved[..., :3] - v_fd)) < 1e-4 * scale
    assert np.max(np.abs(moved[..., 3:] - w_fd)) < 1e-4 * scale


def test_drift_is_the_derivative_of_the_jacobian_along_the_motion(case):
    """Gdot_i thetadot = (d G_i / dt) thetadot (eq. 4)."""
    s, law = case
    t = np.linspace(0.0, 1.0, 21)
    q, qd, _ = trajectory(law, t)
    h = 1e-5
    g_dot = (s.cog_jacobians(np.array(law(t + h)).T) - s.cog_jacobians(np.array(law(t - h)).T)) / (2 * h)
    expected = np.einsum('nlrm,nm->nlr', g_dot, qd)
    drift = s.cog_drifts(q, qd)
    assert np.max(np.abs(drift - expected)) < 1e-4 * (1.0 + np.max(np.abs(expected)))


def test_power_of_the_torques_is_the_rate_of_energy(case):
    """sum tau_k thetadot_k = dE/dt (kinetic + potential) along a trajectory."""
    s, law = case
    m = s.mechanism
    t = np.linspace(0.0, 1.0, 2001)
    q, qd, qdd = trajectory(law, t)
    tau = s.torques(q, qd, qdd)
    s.reset()
    g = s.cog_jacobians(q)
    positions, rotations = s.cog_poses(q)
    motion = np.einsum('nlrm,nm->nlr', g, qd)
    v, w = motion[..., :3], motion[..., 3:]
    mass = np.array(m.link_mass)
    inertia = np.array(m.link_inertia).reshape(-1, 3, 3)
    world_inertia = rotations @ inertia @ np.swapaxes(rotations, -1, -2)
    kinetic = 0.5 * (np.einsum('l,nlr,nlr->n', mass, v, v) +
                     np.einsum('nlr,nlrs,nls->n', w, world_inertia, w))
    potential = -np.einsum('l,nlr,r->n', mass, positions, np.array(m.gravity))
    energy = kinetic + potential
    de_dt = np.gradient(energy, t, edge_order=2)
    power = np.sum(tau * qd, axis=1)
    inner = slice(5, -5)
    scale = np.max(np.abs(power)) + 1.0
    assert np.max(np.abs(power[inner] - de_dt[inner])) < 1e-4 * scale
