"""The paper's example (Fig. 2): the parallelogram four-bar, (a) one actuator, (b) two."""
from mechanisms import from_yaml, with_changes
import numpy as np
import pytest

import cog_id_ros

M_LINK, L, G = 1.0, 0.5, 9.81


def target(n=401):
    """Paper Fig. 3 (our reading): theta(t) = pi/2 + 0.5 sin(pi t), t in [0, 2] s."""
    t = np.linspace(0.0, 2.0, n)
    return (t, np.pi / 2 + 0.5 * np.sin(np.pi * t), 0.5 * np.pi * np.cos(np.pi * t),
            -0.5 * np.pi ** 2 * np.sin(np.pi * t))


def closed_form(theta, thetaddot):
    """Parallelogram: T = (1/2)(2 m L^2/3 + m L^2) thetadot^2, V = 2 m g L sin(theta)."""
    return (5.0 / 3.0) * M_LINK * L ** 2 * thetaddot + 2.0 * M_LINK * G * L * np.cos(theta)


def solver(name, **changes):
    params = with_changes(from_yaml(f'config/{name}.yaml'), **changes)
    return cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params))


def test_a_matches_closed_form_batch_and_per_sample():
    _, th, thd, thdd = target()
    exact = closed_form(th, thdd)
    s = solver('paper_four_bar_a')
    batch = s.torques(th[:, None], thd[:, None], thdd[:, None])
    s.reset()
    single = np.array([s.torques([a], [b], [c]) for a, b, c in zip(th, thd, thdd)])
    peak = np.max(np.abs(exact))
    assert np.max(np.abs(batch[:, 0] - exact)) < 1e-10 * peak
    assert np.max(np.abs(single[:, 0] - exact)) < 1e-10 * peak


def test_b_is_the_minimum_norm_pair_doing_the_same_work_as_a():
    _, th, thd, thdd = target()
    two = np.column_stack([th, th])
    tau_b = solver('paper_four_bar_b').torques(two, np.column_stack([thd, thd]),
                                               np.column_stack([thdd, thdd]))
    tau_a = solver('paper_four_bar_a').torques(th[:, None], thd[:, None], thdd[:, None])[:, 0]
    peak = np.max(np.abs(tau_a))
    # same motion: the same power (virtual work) at every instant
    assert np.max(np.abs((tau_b[:, 0] + tau_b[:, 1]) * thd - tau_a * thd)) < 1e-10 * peak
    # every pair (t1, t3) with t1 + t3 = tau_a produces it; the least-norm one splits it evenly
    assert np.max(np.abs(tau_b - tau_a[:, None] / 2)) < 1e-10 * peak


def test_b_with_torque_weights_minimises_the_weighted_sum():
    _, th, thd, thdd = target(101)
    s = solver('paper_four_bar_b', mechanism__torque_weights=[1.0, 2.0])
    tau = s.torques(np.column_stack([th, th]), np.column_stack([thd, thd]),
                    np.column_stack([thdd, thdd]))
    total = closed_form(th, thdd)
    # min t1^2 + 2 t3^2 with t1 + t3 = total: t1 = 2/3 total, t3 = 1/3 total
    assert np.allclose(tau[:, 0], 2 * total / 3, atol=1e-10 * np.max(np.abs(total)))
    assert np.allclose(tau[:, 1], total / 3, atol=1e-10 * np.max(np.abs(total)))


@pytest.mark.parametrize('name', ['paper_four_bar_a', 'paper_four_bar_b'])
def test_equation_of_motion_reproduces_torques(name):
    _, th, thd, thdd = target(51)
    m = 1 if name.endswith('a') else 2
    q, qd, qdd = (np.tile(x[:, None], (1, m)) for x in (th, thd, thdd))
    s = solver(name)
    h, b = s.equation_of_motion(q, qd)
    assert h.shape == (51, m, m) and b.shape == (51, m)
    tau = s.torques(q, qd, qdd)
    assert np.allclose(np.einsum('nij,nj->ni', h, qdd) + b, tau, atol=1e-12, rtol=0)
    if m == 1:
        assert np.allclose(h[:, 0, 0], 5.0 / 3.0 * M_LINK * L ** 2)
