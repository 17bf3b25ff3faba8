"""Joint space and actuator space (core/transmission/): the map both ways, exact.

How we know (issue "Joint space and actuator space"): positions both ways agree with an
independent closure solve (written here from the geometry, not the package's kinematics) to
1e-9; power is kept, tau_m . theta_dot = tau_q . q_dot; the Jacobian agrees with finite
differences of the positions; the joint-space torques of a motion equal the actuator-space
torques of the same motion; batch and per-sample agree; every backend the same.
"""
import math

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros import (
    InverseDynamics,
    Mechanism,
    MechanismConfigError,
    SetpointError,
    SingularConfigurationError,
    Transmission,
)

ANKLE = 'config/parallel_ankle.yaml'
KNEE = 'config/four_bar_knee.yaml'
LEG = 'config/talos_like_leg.yaml'      # the published TALOS-like leg, its joint space named
BACKENDS = ['reference', 'python', 'native']


@pytest.fixture(scope='module')
def ankle():
    return Mechanism.from_params_file(ANKLE)


@pytest.fixture(scope='module')
def knee():
    return Mechanism.from_params_file(KNEE)


def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def ankle_motors(pitch, roll):
    """The motor angles of an ankle pose from the geometry of config/parallel_ankle.yaml
    alone: each crank tip 0.27 m from its rod's ball on the foot (bisection near 0)."""
    out = []
    for side in (1.0, -1.0):
        ball = rot_y(pitch) @ rot_x(roll) @ np.array([-0.05, 0.03 * side, -0.02])
        motor = np.array([0.0, 0.03 * side, 0.25])

        def gap(theta):
            tip = motor + rot_y(theta) @ np.array([-0.05, 0.0, 0.0])
            return np.linalg.norm(tip - ball) - 0.27
        lo, hi = -1.0, 1.0
        assert gap(lo) * gap(hi) < 0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if gap(lo) * gap(mid) > 0 else (lo, mid)
        out.append(0.5 * (lo + hi))
    return np.array(out)


def knee_angle(theta):
    """The knee angle of a motor angle from config/four_bar_knee.yaml's geometry alone
    (planar x-z; a rotation about y by a takes (x, z) to (x cos a + z sin a, -x sin a +
    z cos a)): the shin's lever pin 0.18682 m from the crank tip (bisection near 0)."""
    def turn(a, x, z):
        return np.array([x * math.cos(a) + z * math.sin(a), -x * math.sin(a) + z * math.cos(a)])
    tip = np.array([-0.05, 0.15]) + turn(theta, -0.05, 0.0)
    length = math.hypot(0.05, 0.18)

    def gap(q):
        return np.linalg.norm(turn(q, -0.05, -0.03) - tip) - length
    lo, hi = -0.8, 0.8
    assert gap(lo) * gap(hi) < 0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if gap(lo) * gap(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize('backend', BACKENDS)
def test_ankle_positions_both_ways_agree_with_an_independent_closure_solve(ankle, backend):
    tr = Transmission(ankle, backend)
    rng = np.random.default_rng(1)
    for pitch, roll in rng.uniform([-0.5, -0.3], [0.5, 0.3], (12, 2)):
        theta = ankle_motors(pitch, roll)
        assert np.allclose(tr.to_actuator_space([pitch, roll]), theta, atol=1e-9, rtol=0)
        assert np.allclose(tr.to_joint_space(theta), [pitch, roll], atol=1e-9, rtol=0)


def test_knee_positions_both_ways_agree_with_an_independent_closure_solve(knee):
    tr = InverseDynamics(knee).transmission
    for theta in np.linspace(-0.5, 0.6, 12):
        q = knee_angle(theta)
        assert tr.to_joint_space([theta])[0] == pytest.approx(q, abs=1e-9)
        assert tr.to_actuator_space([q])[0] == pytest.approx(theta, abs=1e-9)


@pytest.mark.parametrize('path', [ANKLE, KNEE, LEG])
def test_power_is_kept_and_the_jacobian_is_the_derivative_of_the_positions(path):
    mech = Mechanism.from_params_file(path)
    tr = Transmission(mech)
    rng = np.random.default_rng(2)
    m = len(mech.active_joints)
    for _ in range(8):
        theta = np.array(mech.assembled_positions)[mech.active_index] + rng.uniform(-0.3, 0.3, m)
        theta_dot, tau_q = rng.normal(size=m), rng.normal(size=m) * 10
        q_dot = tr.joint_velocities(theta, theta_dot)
        tau_m = tr.actuator_efforts(theta, tau_q)
        assert tau_m @ theta_dot == pytest.approx(tau_q @ q_dot, rel=1e-9, abs=1e-12)
        back = tr.joint_efforts(theta, tau_m)
        assert np.allclose(back, tau_q, rtol=1e-9, atol=1e-9)
        q = tr.to_joint_space(theta)
        assert np.allclose(tr.actuator_velocities(q, q_dot), theta_dot, rtol=1e-9, atol=1e-9)
        jac, h = tr.jacobian(theta), 1e-6
        numeric = np.array([(tr.to_joint_space(theta + h * e) - tr.to_joint_space(theta - h * e))
                            / (2 * h) for e in np.eye(m)]).T
        assert np.allclose(jac, numeric, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize('path, joint_space', [
    (ANKLE, None), (KNEE, None), (LEG, None),
    (ANKLE, ['ankle_pitch', 'motor_left']),     # the pitch coupled to a motor named too
])
def test_one_sample_of_joint_efforts_equals_the_exact_map(path, joint_space):
    """joint_efforts of one sample inverts J at once, only its block beside the joints that
    are motors too (the TALOS-like leg's hip and knee); the batch takes K from the joints'
    solver at each q. Both agree, and NaN or infinite efforts are refused, never mapped."""
    mech = Mechanism.from_params_file(path)
    if joint_space is not None:
        params = mech.settled_parameters()
        params['mechanism.joint_space'] = joint_space
        mech = Mechanism.from_parameters(params)
    tr, batch = Transmission(mech), Transmission(mech)
    rng = np.random.default_rng(5)
    m = len(mech.active_joints)
    home = np.array(mech.assembled_positions)[mech.active_index]
    thetas = home + rng.uniform(-0.15, 0.15, (6, m))    # (the joints within their limits)
    tau_m = rng.normal(size=(6, m)) * 10
    one = np.array([tr.joint_efforts(theta, tau) for theta, tau in zip(thetas, tau_m)])
    exact = batch.joint_efforts(thetas, tau_m)
    assert np.allclose(one, exact, rtol=1e-9, atol=1e-9 * np.abs(exact).max())
    if tr._blocks.unit:     # the leg: its motors in the joint space take their own effort
        for i, k in tr._blocks.unit:
            assert not np.allclose(one[:, i], 0.0)
    for bad in (math.nan, math.inf):
        for call in (tr.joint_efforts, tr.actuator_efforts, tr.joint_velocities):
            with pytest.raises(SetpointError) as err:
                call(thetas[0], [bad] + [1.0] * (m - 1))
            assert err.value.reason == 'non_finite'


def with_joint_space(path, joint_space):
    params = Mechanism.from_params_file(path).settled_parameters()
    params['mechanism.joint_space'] = joint_space
    return Mechanism.from_parameters(params)


def test_no_map_gives_a_nan_or_infinite_number():
    """An adversarial pass: batches, a redundant mechanism's one sample and finite inputs
    too large mapped NaN or inf silently (only one sample of a square map refused them).
    Every map now refuses: non_finite for NaN or infinite inputs, out_of_range where finite
    ones overflow; a batch names the sample."""
    tr = Transmission(Mechanism.from_params_file(ANKLE))
    zeros = np.zeros((3, 2))
    bad = np.ones((3, 2))
    bad[1, 0] = math.nan
    for call in (tr.joint_velocities, tr.actuator_efforts, tr.joint_efforts):
        with pytest.raises(SetpointError) as err:
            call(zeros, bad)
        assert err.value.reason == 'non_finite' and err.value.sample == 1, err.value
    q = tr.to_joint_space(zeros)
    with pytest.raises(SetpointError) as err:
        tr.actuator_velocities(q, bad)
    assert err.value.reason == 'non_finite' and err.value.sample == 1
    coupled = Transmission(with_joint_space(ANKLE, ['ankle_pitch', 'motor_left']))
    with pytest.raises(SetpointError) as err:
        coupled.actuator_velocities(coupled.to_joint_space([0.0, 0.0]), [1e308, 1.0])
    assert err.value.reason == 'out_of_range'
    redundant = Transmission(with_joint_space('config/five_bar_redundant.yaml', ['j1', 'j5']))
    theta = np.array(redundant.mechanism.assembled_positions)[redundant.mechanism.active_index]
    with pytest.raises(SetpointError) as err:
        redundant.joint_efforts(theta, [math.nan, 1.0, 1.0])
    assert err.value.reason == 'non_finite'


@pytest.mark.parametrize('vector', [b'12', '12', {1.0, 2.0}, {'a': 1.0, 'b': 2.0},
                                    [1j, 2.0], [True, 1.0]])
def test_velocities_and_efforts_are_real_numbers(ankle, vector):
    """Bytes, a string, a set, a dict, complex numbers and truth values were taken as
    efforts (b'12' as [49, 50]); refused, saying what came."""
    with pytest.raises(SetpointError, match='expected 2 real numbers'):
        Transmission(ankle).joint_efforts([0.0, 0.0], vector)
    assert Transmission(ankle).joint_efforts([0.0, 0.0], [np.float32(1.0), np.int64(2)]).shape \
        == (2,)


def test_a_batch_of_joint_efforts_keeps_the_motors_branch_past_the_toggle(knee):
    """Past the knee's toggle (motor at 1.64 rad, the knee coming back from its peak) the
    batch took K at the knee angle from the joints' solver, which takes the other motor
    angle of that knee angle: the sign of the knee's effort came out wrong. The batch
    follows the per-sample rule now, as one sample does."""
    one, batch = Transmission(knee), Transmission(knee)
    walk = np.arange(0.0, 1.64, 0.005)
    for theta in walk:
        one.to_joint_space([theta])
    tau_q = one.joint_efforts([1.64], [1.0])
    efforts = batch.joint_efforts(np.append(walk, 1.64)[:, None], np.ones((len(walk) + 1, 1)))
    assert efforts[-1] == pytest.approx(tau_q, rel=1e-12)
    rate = one.joint_velocities([1.64], [1.0])
    assert tau_q[0] * rate[0] == pytest.approx(1.0, rel=1e-9)      # power: tau_m = 1, rate 1


@pytest.mark.parametrize('path', [ANKLE, KNEE, LEG])
def test_joint_space_torques_of_a_motion_equal_the_actuator_torques_of_the_same_motion(path):
    """The exact motor torques of a joint-space motion (the rods' inertia and gravity in
    them) are the actuator-space torques of the motors' motion it makes; and forward
    dynamics in joint space undoes them."""
    mech = Mechanism.from_params_file(path)
    solver = InverseDynamics(mech)
    tr = solver.transmission
    d = len(mech.joint_space)
    amplitude = np.linspace(0.3, 0.15, d)
    q0 = tr.to_joint_space(np.array(mech.assembled_positions)[mech.active_index])

    def motion(t):
        return (q0 + amplitude * np.sin(2.0 * t + 0.3), amplitude * 2.0 * np.cos(2.0 * t + 0.3),
                -amplitude * 4.0 * np.sin(2.0 * t + 0.3))
    reference = InverseDynamics(mech)
    for t in np.linspace(0.0, 1.5, 7):
        q, qd, qdd = motion(t)
        tau = solver.torques(q, qd, qdd, space='joint')
        theta = tr.to_actuator_space(q)
        theta_dot = tr.actuator_velocities(q, qd)
        h = 1e-5
        theta_ddot = (tr.actuator_velocities(*motion(t + h)[:2])
                      - tr.actuator_velocities(*motion(t - h)[:2])) / (2 * h)
        exact = reference.torques(theta, theta_dot, theta_ddot)
        assert np.allclose(tau, exact, rtol=1e-6, atol=1e-6 * np.abs(exact).max()), (t, tau, exact)
        back = solver.forward_dynamics(q, qd, tau, space='joint')
        assert np.allclose(back, qdd, rtol=1e-7, atol=1e-7)


def test_batches_follow_the_per_sample_rule(ankle):
    tr, one = Transmission(ankle), Transmission(ankle)
    q = np.column_stack([0.4 * np.sin(np.linspace(0, 3, 40)), 0.2 * np.cos(np.linspace(0, 3, 40))])
    qd = np.full_like(q, 0.3)
    theta = tr.to_actuator_space(q)
    assert theta.shape == (40, 2)
    assert np.allclose(theta, [one.to_actuator_space(row) for row in q], rtol=0, atol=1e-13)
    assert np.allclose(tr.to_joint_space(theta), q, atol=1e-9, rtol=0)
    assert tr.jacobian(theta).shape == (40, 2, 2)
    tau = np.column_stack([np.sin(np.arange(40.0)), np.cos(np.arange(40.0))])
    assert np.allclose(tr.joint_efforts(theta, tau),
                       [one.joint_efforts(a, b) for a, b in zip(theta, tau)], rtol=1e-9)
    assert np.allclose(tr.actuator_velocities(q, qd),
                       [one.actuator_velocities(a, b) for a, b in zip(q, qd)], rtol=1e-12)
    batch = InverseDynamics(ankle).torques(q, qd, np.zeros_like(q), space='joint')
    each = InverseDynamics(ankle)
    assert np.allclose(batch, [each.torques(a, b, [0.0, 0.0], space='joint')
                               for a, b in zip(q, qd)], rtol=1e-10, atol=1e-12)


def test_a_redundant_mechanism_gets_the_least_weighted_norm_efforts():
    """five_bar_redundant (three motors, two freedoms) with its end effector's two joints
    as joint space: actuator_efforts is power-consistent and of least weighted norm."""
    base = Mechanism.from_params_file('config/five_bar_redundant.yaml')
    passive = [j for j in base.joints if j not in base.active_joints
               and base.joint_types[base.joints.index(j)] == 'revolute']
    params = dict(base.settled_parameters(), **{'mechanism.joint_space': passive[:2],
                                                'mechanism.torque_weights': [1.0, 2.0, 4.0]})
    mech = Mechanism.from_parameters(params)
    tr = Transmission(mech)
    theta = tr.to_actuator_space(tr.to_joint_space(np.array(mech.assembled_positions)[
        mech.active_index]))
    tau_q = np.array([3.0, -1.0])
    tau_m = tr.actuator_efforts(theta, tau_q)
    k = tr.inverse_jacobian(tr.to_joint_space(theta))
    assert np.allclose(k.T @ tau_m, tau_q, rtol=1e-9, atol=1e-9)
    w = np.array([1.0, 2.0, 4.0])
    null = np.linalg.svd(k.T)[2][-1]                   # efforts that make no joint effort
    for step in (1e-3, -1e-3):
        assert w @ tau_m ** 2 < w @ (tau_m + step * null) ** 2
    assert np.allclose(tr.joint_efforts(theta, tau_m), tau_q, rtol=1e-9, atol=1e-9)
    consistent = tr.to_actuator_space(tr.to_joint_space(theta))
    assert np.allclose(consistent, theta, atol=1e-9)


def test_a_singular_transmission_is_refused_naming_the_joints(knee):
    """The knee's four-bar toggles at about 0.7714 rad (the coupler in line with the
    crank: the knee stops, dq/dtheta -> 0): approaching it, the motor rates and torques that
    one knee rate needs grow without bound; past mechanism.max_condition_number (1e3 here)
    the calls refuse, naming the motor and the knee, never an infinite number."""
    params = knee.settled_parameters()
    params['mechanism.max_condition_number'] = 1e3
    tr = Transmission(Mechanism.from_parameters(params))
    refused = None
    for q in 0.7714 - np.geomspace(0.3, 1e-9, 60):
        try:
            rates = tr.actuator_velocities([q], [1.0])
            torque = InverseDynamics(tr.mechanism).transmission.torques([q], [0.0], [0.0])
        except SingularConfigurationError as err:
            refused = err
            break
        assert np.isfinite(rates).all() and np.isfinite(torque).all()
    assert refused is not None and 0.6 < q < 0.7714
    assert 'motor_knee' in str(refused) and '(knee)' in str(refused)
    assert refused.condition_number > 1e3
    # the motor's efforts on the knee (K^T tau_m) where the motor's crank toggles: J -> 0
    with pytest.raises(SingularConfigurationError) as err:
        for theta in np.linspace(1.62, 1.63, 201):
            assert np.isfinite(tr.joint_efforts([theta], [1.0])).all()
    assert 'motor_knee' in str(err.value) and err.value.condition_number > 1e3


@pytest.mark.parametrize('joint_space, words', [
    (['ankle_pitch'], 'as many joints as the mechanism has degrees of freedom (2)'),
    (['ankle_pitch', 'nowhere'], "'nowhere' is not in mechanism.joints"),
    (['ankle_pitch', 'rod_left_ball'], 'spherical, universal or fixed'),
    (['ankle_pitch', 'ankle_pitch'], 'duplicate'),
])
def test_a_joint_space_that_is_not_one_is_refused_naming_the_parameter(joint_space, words):
    params = Mechanism.from_params_file(ANKLE).settled_parameters()
    params['mechanism.joint_space'] = joint_space
    with pytest.raises(MechanismConfigError) as err:
        Mechanism.from_parameters(params)
    assert err.value.parameter == 'mechanism.joint_space' and words in str(err.value)


def test_a_joint_space_that_misses_a_motion_is_refused_with_the_motion_left():
    """The ankle driven by one motor with its roll locked has one freedom, pitch and both
    motors moving together: a joint space of the locked roll sees none of it."""
    params = Mechanism.from_params_file(ANKLE).settled_parameters()
    params['mechanism.locked_joints'] = ['ankle_roll']
    params['mechanism.active_joints'] = ['motor_left']
    params['mechanism.joint_space'] = ['ankle_roll']
    with pytest.raises(MechanismConfigError) as err:
        Mechanism.from_parameters(params)
    assert err.value.parameter == 'mechanism.joint_space' and 'ankle_roll' in str(err.value)
    from cog_id_ros.core.model.joint_space import seen_condition
    assert seen_condition(np.zeros((1, 1))) == math.inf
    assert seen_condition(np.eye(2)) == 1.0


def test_without_a_joint_space_the_transmission_says_what_to_give():
    mech = Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    with pytest.raises(MechanismConfigError) as err:
        InverseDynamics(mech).torques([1.0], [0.0], [0.0], space='joint')
    assert 'mechanism.joint_space' in str(err.value)
    with pytest.raises(cog_id_ros.SetpointError):
        InverseDynamics(mech).torques([1.0], [0.0], [0.0], space='joints')


def test_a_locked_joint_in_the_joint_space_is_named_as_locked():
    """Adversarial pass: a locked joint was refused as 'rates tied'; it is held, say so."""
    params = Mechanism.from_params_file(LEG).settled_parameters()
    params['mechanism.joint_space'] = ['motor_hip_z', 'motor_hip_x', 'motor_hip_y',
                                       'motor_knee', 'ankle_rod_2_rev2', 'motor_ankle']
    with pytest.raises(MechanismConfigError) as err:
        Mechanism.from_parameters(params)
    assert 'mechanism.locked_joints' in str(err.value) and 'ankle_rod_2_rev2' in str(err.value)


def test_a_joint_space_pose_past_the_toggle_says_so(knee):
    """Adversarial pass: the knee asked past its toggle (0.7714 rad) said only 'send
    setpoints closer together'; the error names the transmission and what is past reach."""
    with pytest.raises(cog_id_ros.ClosureError) as err:
        InverseDynamics(knee).torques([0.78], [0.0], [0.0], space='joint')
    assert 'motor_knee' in str(err.value) and 'past what the linkage can reach' in str(err.value)
