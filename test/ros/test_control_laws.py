"""The feedback laws of cog_id_node against the core's equation of motion (no ROS).

Each mode's command at a measured state is checked against eq. (7) written out with
``equation_of_motion`` (H and B at the measured pose), an independent path through the
core (the batch/pose solver, not the per-sample kernel the modes call), on the paper
four-bar, the five-bar and the Stewart platform; gains, their checks and warnings; and the
measured state checks (stale, non-finite, jump, missing velocities).
"""
import math
import types

import numpy as np
import pytest

pytest.importorskip('rclpy')

from cog_id_ros import InverseDynamics, Mechanism, MechanismConfigError  # noqa: E402
from cog_id_ros.core import ClosureError, SetpointError  # noqa: E402
from cog_id_ros.ros.conversions import Rejected  # noqa: E402
from cog_id_ros.ros.measurement_stream import MeasurementStream  # noqa: E402
from cog_id_ros.ros.modes import FEEDBACK_MODES, make_mode  # noqa: E402
from cog_id_ros.ros.parameters import NODE_PARAMETERS  # noqa: E402

CONFIGS = ['config/paper_four_bar_a.yaml', 'config/five_bar.yaml',
           'config/stewart_6ups_spherical.yaml', 'config/five_bar_redundant.yaml']
# (five_bar_redundant: the five-bar with a third actuator, j3; its states are the five-bar's)


def config_for(mech, **values):
    """A NodeConfig-like object: the table's checked defaults and ``values``."""
    types_ = [mech.joint_types[mech.joints.index(j)] for j in mech.active_joints]
    checked = {name: p.check(values.get(name, p.default), types_)
               for name, p in NODE_PARAMETERS.items()}
    wraps = [k.wraps for k in mech.active_kinds]
    return types.SimpleNamespace(active_joints=tuple(mech.active_joints), unwrap=wraps,
                                 **checked)


def mode_for(mech, name, **values):
    config = config_for(mech, control_mode=name, **values)
    return make_mode(config, InverseDynamics(mech), lambda: InverseDynamics(mech)), config


def states(mech, seed=0):
    """A setpoint and a measured state near the assembled pose (active joints)."""
    rng = np.random.default_rng(seed)
    q0 = np.array([mech.assembled_positions[mech.joints.index(j)]
                   for j in mech.active_joints])
    scale = np.array([0.05 if t == 'revolute' else 0.005 for t in
                      (mech.joint_types[mech.joints.index(j)] for j in mech.active_joints)])
    q_d, q_m = q0 + scale * rng.standard_normal(len(q0)), q0 + scale * rng.standard_normal(len(q0))
    if mech.is_redundant:       # consistent: solved by the five-bar with two actuators
        plain = Mechanism.from_params_file('config/five_bar.yaml')
        solver = InverseDynamics(plain)
        index = [plain.joints.index(j) for j in mech.active_joints]
        q_d = solver.solve_positions(q_d[:2])[index]
        q_m = solver.solve_positions(q_m[:2])[index]
    v_d, v_m, a_d = (10 * scale * rng.standard_normal(len(q0)) for _ in range(3))
    return q_d, v_d, a_d, q_m, v_m


@pytest.mark.parametrize('params', CONFIGS)
def test_computed_torque_is_h_of_the_measured_pose_times_the_commanded_acceleration(params):
    mech = Mechanism.from_params_file(params)
    if mech.is_redundant:
        pytest.skip('redundant: see test_redundant_efforts_are_distributed_as_eq_7')
    mode, _ = mode_for(mech, 'computed_torque', kp=[400.0], kd=[40.0])
    q_d, v_d, a_d, q_m, v_m = states(mech)
    assert mode.efforts(q_d.tolist(), v_d.tolist(), a_d.tolist()) is None   # in force
    tau = np.array(mode.command(q_m.tolist(), v_m.tolist()))
    H, B = InverseDynamics(mech).equation_of_motion(q_m, v_m)
    expected = H @ (a_d + 40.0 * (v_d - v_m) + 400.0 * (q_d - q_m)) + B
    assert np.allclose(tau, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    assert np.allclose(mode.error, q_d - q_m)


@pytest.mark.parametrize('params', CONFIGS[:3])
def test_pd_feedforward_is_the_setpoint_dynamics_plus_pd(params):
    mech = Mechanism.from_params_file(params)
    kp, kd = np.arange(1, len(mech.active_joints) + 1) * 50.0, 3.0
    mode, _ = mode_for(mech, 'pd_feedforward', pd_kp=kp.tolist(), pd_kd=[kd])
    q_d, v_d, a_d, q_m, v_m = states(mech, 1)
    mode.efforts(q_d.tolist(), v_d.tolist(), a_d.tolist())
    tau = np.array(mode.command(q_m.tolist(), v_m.tolist()))
    H, B = InverseDynamics(mech).equation_of_motion(q_d, v_d)
    expected = H @ a_d + B + kp * (q_d - q_m) + kd * (v_d - v_m)
    assert np.allclose(tau, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize('params', CONFIGS)
def test_gravity_compensation_is_b_at_rest_and_needs_no_setpoint(params):
    mech = Mechanism.from_params_file(params)
    mode, _ = mode_for(mech, 'gravity_compensation')
    _, _, _, q_m, v_m = states(mech, 2)
    tau = np.array(mode.command(q_m.tolist(), v_m.tolist()))
    _, B = InverseDynamics(mech).equation_of_motion(q_m, np.zeros(len(q_m)))
    assert np.allclose(tau, B, rtol=1e-9, atol=1e-12 + 1e-9 * np.abs(B).max())
    assert mode.error == [] and not mode.needs_velocities


def test_redundant_efforts_are_distributed_as_eq_7():
    """Five-bar with three actuators: computed torque moves the independent coordinates
    (the primary actuators) exactly as the law asks (forward dynamics of its efforts), and
    its efforts are the weighted minimum-norm torques of that motion (eq. (7))."""
    red = Mechanism.from_params_file('config/five_bar_redundant.yaml')
    mode, _ = mode_for(red, 'computed_torque', kp=[400.0], kd=[40.0])
    q_d, v_d, a_d, q_m, _ = states(red, 3)
    v_d = v_m = np.zeros(len(q_d))
    a_d = np.zeros(len(q_d))
    mode.efforts(q_d.tolist(), v_d.tolist(), a_d.tolist())
    tau = np.array(mode.command(q_m.tolist(), v_m.tolist()))
    # the efforts move the independent coordinates as the law wants (forward dynamics)
    qdd = InverseDynamics(red).forward_dynamics(q_m, v_m, tau)
    primary = red.primary
    assert np.allclose(qdd[primary], 400.0 * (q_d - q_m)[primary], rtol=1e-9, atol=1e-9)
    # and they are eq. (7)'s distribution: the weighted minimum-norm torques of that motion
    assert np.allclose(tau, InverseDynamics(red).torques(q_m, v_m, qdd), rtol=1e-9, atol=1e-9)


def test_redundant_pd_efforts_act_on_the_independent_coordinates_as_eq_7():
    """Five-bar with three actuators: the PD efforts are eq. (7)'s distribution of the
    force the per-joint PD makes on the independent coordinates: the same motion as the
    per-joint efforts, and within the span of every torque eq. (7) gives (no actuator set
    against another)."""
    red = Mechanism.from_params_file('config/five_bar_redundant.yaml')
    kp, kd = [50.0, 70.0, 90.0], [3.0, 4.0, 5.0]
    mode, _ = mode_for(red, 'pd_feedforward', pd_kp=kp, pd_kd=kd)
    q_d, v_d, a_d, q_m, _ = states(red, 4)
    v_d = v_m = np.zeros(len(q_d))
    mode.efforts(q_d.tolist(), v_d.tolist(), np.zeros(len(q_d)).tolist())
    ff = np.array(mode.setpoint[3])
    pd = np.array(mode.command(q_m.tolist(), v_m.tolist())) - ff
    per_joint = np.array(kp) * (q_d - q_m)
    assert np.abs(pd - per_joint).max() > 1e-3 * np.abs(per_joint).max()   # not as given
    solver = InverseDynamics(red)
    primary = red.primary
    same = solver.forward_dynamics(q_m, v_m, ff + pd)[primary]
    assert np.allclose(same, solver.forward_dynamics(q_m, v_m, ff + per_joint)[primary],
                       rtol=1e-9, atol=1e-9)
    # eq. (7)'s torques at q_m span W^-1 V_a: two motions and rest give two directions
    rest = solver.torques(q_m, v_m, np.zeros(3))
    span = np.array([solver.torques(q_m, v_m, qdd) - rest
                     for qdd in (solver.forward_dynamics(q_m, v_m, rest + e)
                                 for e in np.eye(3)[:2])]).T
    coef, *_ = np.linalg.lstsq(span, pd, rcond=None)
    assert np.allclose(span @ coef, pd, rtol=1e-9, atol=1e-9 * np.abs(pd).max())
    # and the ordinary five-bar (no redundancy) keeps the per-joint PD as given
    plain = Mechanism.from_params_file('config/five_bar.yaml')
    mode, _ = mode_for(plain, 'pd_feedforward', pd_kp=kp[:2], pd_kd=kd[:2])
    mode.efforts(q_d[:2].tolist(), [0.0, 0.0], [0.0, 0.0])
    tau = np.array(mode.command(q_m[:2].tolist(), [0.0, 0.0]))
    assert np.allclose(tau - mode.setpoint[3], per_joint[:2], rtol=1e-12, atol=1e-12)


def test_a_measured_pose_whose_loops_cannot_close_raises_and_no_command():
    mech = Mechanism.from_params_file('config/stewart_6ups_spherical.yaml')
    for name in FEEDBACK_MODES:
        mode, _ = mode_for(mech, name, pd_kp=[10.0])
        mode.efforts([0.1326] * 6, [0.0] * 6, [0.0] * 6)
        with pytest.raises(ClosureError):
            mode.command([1.1326] + [0.1326] * 5, [0.0] * 6)    # one leg 1 m too long


def test_before_a_setpoint_the_first_measured_pose_is_held():
    mech = Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    mode, _ = mode_for(mech, 'computed_torque')
    tau = mode.command([1.2], [0.0])
    assert mode.setpoint[0] == [1.2] and mode.error == [0.0]
    assert np.allclose(tau, InverseDynamics(mech).torques([1.2], [0.0], [0.0]))
    mode.efforts([1.3], [0.5], [0.1])
    mode.setpoints_stopped()            # the setpoint stream stopped: in force at rest
    assert mode.setpoint[:3] == ([1.3], [0.0], [0.0])


def test_error_of_a_revolute_joint_is_taken_within_a_turn():
    mech = Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    mode, _ = mode_for(mech, 'computed_torque')
    mode.efforts([1.5 + 2 * math.pi], [0.0], [0.0])
    mode.command([1.4], [0.0])
    assert mode.error == pytest.approx([0.1])


@pytest.mark.parametrize('name, value', [('kp', [-1.0]), ('kd', [math.nan]),
                                         ('pd_kp', [1.0, 2.0, 3.0]), ('pd_kd', 'x')])
def test_gains_are_checked(name, value):
    with pytest.raises(MechanismConfigError) as error:
        NODE_PARAMETERS[name].check(value, ['revolute', 'revolute'])
    assert error.value.parameter == name


def test_underdamped_gains_are_warned_about():
    mech = Mechanism.from_params_file('config/five_bar.yaml')
    mode, _ = mode_for(mech, 'computed_torque', kp=[400.0], kd=[40.0])
    assert mode.gain_warnings() == []
    mode, _ = mode_for(mech, 'computed_torque', kp=[400.0], kd=[40.0, 10.0])
    (warning,) = mode.gain_warnings()
    assert 'underdamped' in warning and 'j5 (damping ratio 0.25)' in warning
    mode, _ = mode_for(mech, 'pd_feedforward', pd_kp=[100.0], pd_kd=[0.1])
    assert 'underdamped' in mode.gain_warnings()[0]
    mode, _ = mode_for(mech, 'pd_feedforward')
    assert 'no feedback' in mode.gain_warnings()[0]


class Msg:
    def __init__(self, names, position, velocity=()):
        self.name, self.position, self.velocity, self.effort = names, position, velocity, []


def test_a_corrupt_measured_velocity_never_reaches_the_motors():
    """A finite but absurd velocity (an encoder's glitch, a unit error) would reach the
    efforts through kd and the velocity terms: rejected beyond max_measured_velocity."""
    mech = Mechanism.from_params_file('config/five_bar.yaml')
    names = list(mech.active_joints)
    stream = MeasurementStream(config_for(mech), needs_velocities=True)
    for bad_rate in (1e3, -1e6, 1e150):
        with pytest.raises(Rejected) as bad:
            stream.take(Msg(names, [2.0, 1.14], [bad_rate, 0.0]))
        assert bad.value.reason == 'velocity' and 'max_measured_velocity' in str(bad.value)
    assert stream.take(Msg(names, [2.0, 1.14], [150.0, -150.0]))[1] == [150.0, -150.0]
    free = MeasurementStream(config_for(mech, max_measured_velocity=[math.inf]), True)
    assert free.take(Msg(names, [2.0, 1.14], [1e6, 0.0]))[1] == [1e6, 0.0]
    slow = MeasurementStream(config_for(mech, max_measured_velocity=[1.0, 2.0]), True)
    with pytest.raises(Rejected):
        slow.take(Msg(names, [2.0, 1.14], [0.5, 2.5]))


def test_a_measured_pose_beyond_a_position_limit_is_commanded_back():
    """The URDF five-bar's motor/1 overshoots its limit (3 rad): the setpoint there is
    refused ('limit'), the measured pose is served, and computed torque pulls it back."""
    mech = Mechanism.from_params_file('config/five_bar_robot.yaml')
    mode, _ = mode_for(mech, 'computed_torque', kp=[400.0], kd=[40.0])
    with pytest.raises(SetpointError) as refused:
        InverseDynamics(mech).sample_torques([3.05, 0.0])
    assert refused.value.reason == 'limit'
    mode.efforts([2.9, 0.0], [0.0, 0.0], [0.0, 0.0])
    tau = np.array(mode.command([3.05, 0.0], [0.0, 0.0]))
    solver = InverseDynamics(mech)
    solver.check_position_limits = False
    solver.sample_torques([2.9, 0.0])          # the same branch as the mode's solver
    qdd = solver.forward_dynamics([3.05, 0.0], [0.0, 0.0], tau)
    assert np.allclose(qdd, [400.0 * (2.9 - 3.05), 0.0], rtol=1e-7, atol=1e-7)


def test_redundant_computed_torque_warns_only_about_the_gains_it_uses():
    """Five-bar with three actuators: the law acts on the primary ones (j1, j5); j3's gains
    are said to be unused, not checked as if they acted."""
    red = Mechanism.from_params_file('config/five_bar_redundant.yaml')
    mode, _ = mode_for(red, 'computed_torque', kp=[400.0, 400.0, 1.0], kd=[40.0, 40.0, 0.1])
    warnings = mode.gain_warnings()
    assert len(warnings) == 1 and 'j3 are not used' in warnings[0], warnings
    mode, _ = mode_for(red, 'computed_torque', kp=[400.0, 1.0, 400.0], kd=[40.0, 0.1, 40.0])
    assert any('underdamped' in w and 'j5' in w for w in mode.gain_warnings())
    mode, _ = mode_for(red, 'computed_torque', kp=[400.0], kd=[40.0])
    assert mode.gain_warnings() == []


def test_measured_states_checked():
    mech = Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    config = config_for(mech, measurement_timeout=0.1)
    stream = MeasurementStream(config, needs_velocities=True)
    names = ['joint3']
    with pytest.raises(Rejected) as bad:
        stream.take(Msg(names, [1.0]))
    assert bad.value.reason == 'malformed'                   # no velocities
    with pytest.raises(Rejected) as bad:
        stream.take(Msg(names, [math.nan], [0.0]))
    assert bad.value.reason == 'non_finite'
    import time
    with pytest.raises(Rejected) as bad:
        stream.take(Msg(names, [1.0], [0.0]), {'source_timestamp': time.time_ns() - 200_000_000})
    assert bad.value.reason == 'stale'
    assert stream.take(Msg(names, [1.0], [0.0])) == ([1.0], [0.0])
    stream.accept()
    with pytest.raises(Rejected) as bad:
        stream.take(Msg(names, [1.3], [0.0]))               # 0.3 rad in one step
    assert bad.value.reason == 'jump'
    assert stream.take(Msg(names, [1.1 - 2 * math.pi], [0.0]))[0] == pytest.approx([1.1])


def test_a_gap_longer_than_the_timeout_restarts_the_stream_before_the_timer_judges_it():
    """Reliability item 2 (issue 32): the node stopped longer than measurement_timeout, its
    timer not yet run: the fresh measured state is not a jump from the pose before the gap
    and is commanded from at once (a simulator in lockstep sends no second one before a
    command); after a timeout the timer judged, two must agree (the restart rule). The
    timer's stopped_for counts the silence from when the node ran again (``since``)."""
    import time
    mech = Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    stream = MeasurementStream(config_for(mech, measurement_timeout=0.1), needs_velocities=True)
    names = ['joint3']
    stream.take(Msg(names, [1.0], [0.0]))
    stream.accept()
    time.sleep(0.12)                                       # the gap (a stopped node)
    assert not stream.stopped_for(0.1, since=time.monotonic())   # woke just now: not yet
    assert stream.take(Msg(names, [1.3], [0.0]))[0] == [1.3]     # 0.3 rad on: not a jump
    stream.accept()
    with pytest.raises(Rejected) as bad:
        stream.take(Msg(names, [1.6], [0.0]))               # within the stream: a jump
    assert bad.value.reason == 'jump'
    time.sleep(0.12)
    assert stream.stopped_for(0.1)                          # the timer judged: stopped
    assert not stream.stopped_for(0.1)                      # once
    with pytest.raises(Rejected) as bad:
        stream.take(Msg(names, [0.2], [0.0]))               # after it: a candidate only
    assert bad.value.reason == 'restart'
    assert stream.take(Msg(names, [0.21], [0.0]))[0] == [0.21]


def test_a_position_beyond_1e9_is_out_of_range_never_unwrapped():
    """Adversarial pass (issue 29/32): 1e20 in a measured state or a setpoint was unwrapped
    to an ordinary angle (served as about 0), or became the restart candidate every later
    state agreed with (the controller silent for good). It is refused as out_of_range
    before anything is done with it, and the stream goes on."""
    import time
    mech = Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    stream = MeasurementStream(config_for(mech, measurement_timeout=0.1), needs_velocities=True)
    names = ['joint3']
    stream.take(Msg(names, [1.0], [0.0]))
    stream.accept()
    for bad_value in (1e20, -3e9):
        with pytest.raises(Rejected) as bad:
            stream.take(Msg(names, [bad_value], [0.0]))
        assert bad.value.reason == 'out_of_range'
    time.sleep(0.12)
    assert stream.stopped_for(0.1)
    with pytest.raises(Rejected) as bad:
        stream.take(Msg(names, [1e20], [0.0]))                # never the candidate
    assert bad.value.reason == 'out_of_range'
    with pytest.raises(Rejected) as bad:
        stream.take(Msg(names, [1.0], [0.0]))
    assert bad.value.reason == 'restart'
    assert stream.take(Msg(names, [1.0], [0.0]))[0] == [1.0]
