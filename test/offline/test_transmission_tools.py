"""The offline tools in joint space (docs/transmission.md): ``cog_id_torques --space joint``
(a joint-space CSV in, the motors' torques out, equal to ``InverseDynamics.torques(...,
space='joint')``), ``cog_id_inspect`` drawing both spaces and ``--transmission``, and the
errors that name what to fix.
"""
import math
from pathlib import Path

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.offline import cli
from cog_id_ros.offline import inspect as inspect_tool
from cog_id_ros.offline import trajectory_io as tio

pytest.importorskip('matplotlib')

ROOT = Path(__file__).resolve().parents[2]
ANKLE = ROOT / 'config' / 'parallel_ankle.yaml'
KNEE = ROOT / 'config' / 'four_bar_knee.yaml'
FOUR_BAR = ROOT / 'config' / 'paper_four_bar_a.yaml'


def walking(mech, n=101):
    """A walking-like joint-space motion at 1 Hz: (time, q, qd, qdd) of mech.joint_space."""
    t = np.linspace(0.0, 1.0, n)
    w = 2.0 * math.pi
    amp = {'ankle_pitch': (0.3, 0.0, 0.0), 'ankle_roll': (0.15, 0.5, 0.0),
           'knee': (0.35, 0.0, 0.35)}
    cols = [amp[name] for name in mech.joint_space]
    q = np.column_stack([a * np.sin(w * t + p) + c for a, p, c in cols])
    qd = np.column_stack([a * w * np.cos(w * t + p) for a, p, _ in cols])
    qdd = np.column_stack([-a * w * w * np.sin(w * t + p) for a, p, _ in cols])
    return t, q, qd, qdd


def write_csv(path, columns):
    names = list(columns)
    cells = [list(map(repr, np.asarray(columns[n], dtype=float).tolist())) for n in names]
    path.write_text(','.join(names) + '\n' + '\n'.join(map(','.join, zip(*cells))) + '\n')
    return path


def joint_csv(path, mech, t, q, qd=None, qdd=None, extra=()):
    columns = {'time': t}
    for k, name in enumerate(mech.joint_space):
        columns[f'{name}.position'] = q[:, k]
        if qd is not None:
            columns[f'{name}.velocity'] = qd[:, k]
        if qdd is not None:
            columns[f'{name}.acceleration'] = qdd[:, k]
    for name in extra:
        columns[name] = np.zeros_like(t)
    return write_csv(path, columns)


def run_torques(capsys, *args):
    status = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.mark.parametrize('params', [ANKLE, KNEE], ids=['ankle', 'knee'])
def test_joint_space_csv_gives_the_motor_torques_of_the_core(tmp_path, capsys, params):
    mech = cog_id_ros.Mechanism.from_params_file(str(params))
    t, q, qd, qdd = walking(mech)
    src = joint_csv(tmp_path / 'joint.csv', mech, t, q, qd, qdd,
                    extra=[f'{mech.active_joints[0]}.position'])
    out = tmp_path / 'torques.csv'
    status, stdout, err = run_torques(capsys, '--params-file', params, '--input', src,
                                      '--output', out, '--space', 'joint', '--json')
    assert status == 0, err
    assert 'not a joint-space joint' in err            # the motor's column, ignored
    header, time, efforts = tio.read_efforts(out)
    assert header == ['time'] + [f'{j}.effort' for j in mech.active_joints]
    np.testing.assert_array_equal(time, t)
    exact = cog_id_ros.InverseDynamics(mech).torques(q, qd, qdd, space='joint')
    assert np.abs(efforts - exact).max() <= 1e-9 * max(1.0, np.abs(exact).max())
    # the summary's power is the motors': tau_m . theta_dot = tau_q . q_dot (power kept)
    import json
    summary = json.loads(stdout)
    tr = cog_id_ros.Transmission(mech)
    theta_dot = tr.actuator_velocities(q, qd)
    power = np.abs(efforts * theta_dot).max(axis=0)
    got = [j['peak_power'] for j in summary['joints']]
    np.testing.assert_allclose(got, power, rtol=1e-9)


def test_joint_space_positions_only_are_estimated_as_in_actuator_space(tmp_path, capsys):
    mech = cog_id_ros.Mechanism.from_params_file(str(ANKLE))
    t, q, _, _ = walking(mech, 201)
    src = joint_csv(tmp_path / 'joint.csv', mech, t, q)
    out = tmp_path / 'torques.csv'
    status, _, err = run_torques(capsys, '--params-file', ANKLE, '--input', src,
                                 '--output', out, '--space', 'joint')
    assert status == 0, err
    assert 'ankle_pitch.velocity' in err                # the estimate is said
    traj = tio.read_trajectory(src, mech.joints, mech.joint_space)
    from cog_id_ros.offline import samples
    qq, qd, qdd, _ = samples.setpoints(traj, mech.joint_space)
    exact = cog_id_ros.InverseDynamics(mech).torques(qq, qd, qdd, space='joint')
    assert np.abs(tio.read_efforts(out)[2] - exact).max() <= 1e-9


def test_a_mechanism_without_joint_space_is_named(tmp_path, capsys):
    src = write_csv(tmp_path / 'a.csv', {'time': [0.0, 0.1], 'joint3.position': [1.0, 1.1]})
    out = tmp_path / 'torques.csv'
    status, _, err = run_torques(capsys, '--params-file', FOUR_BAR, '--input', src,
                                 '--output', out, '--space', 'joint')
    assert status == 3
    assert 'mechanism.joint_space' in err and 'without --space joint' in err
    assert not out.exists()


def test_a_missing_joint_space_column_is_named(tmp_path, capsys):
    src = write_csv(tmp_path / 'a.csv', {'time': [0.0, 0.1], 'ankle_pitch.position': [0., 0.],
                                         'motor_right.position': [0.0, 0.0]})
    out = tmp_path / 'torques.csv'
    status, _, err = run_torques(capsys, '--params-file', ANKLE, '--input', src,
                                 '--output', out, '--space', 'joint')
    assert status == 1
    assert "missing column 'ankle_roll.position'" in err
    assert 'joint-space joint ankle_roll' in err
    assert not out.exists()


def test_a_knee_past_its_toggle_is_a_named_row(tmp_path, capsys):
    mech = cog_id_ros.Mechanism.from_params_file(str(KNEE))
    t = np.linspace(0.0, 1.0, 21)
    q = (0.5 + 0.4 * t)[:, None]                        # 0.5 .. 0.9 rad: past 0.7714
    src = joint_csv(tmp_path / 'k.csv', mech, t, q, np.full_like(q, 0.4), np.zeros_like(q))
    out = tmp_path / 'torques.csv'
    status, _, err = run_torques(capsys, '--params-file', KNEE, '--input', src,
                                 '--output', out, '--space', 'joint')
    assert status == 1 and "'knee.position'" in err and 'row ' in err
    status, _, err = run_torques(capsys, '--params-file', KNEE, '--input', src,
                                 '--output', out, '--space', 'joint', '--skip-invalid')
    assert status == 0, err
    _, _, efforts = tio.read_efforts(out)
    solved = ~np.isnan(efforts[:, 0])
    assert solved[:6].all() and not solved[-1]
    exact = cog_id_ros.InverseDynamics(mech).torques(q[solved], np.full((solved.sum(), 1), 0.4),
                                                    np.zeros((solved.sum(), 1)), space='joint')
    assert np.abs(efforts[solved] - exact).max() <= 1e-9


# --- cog_id_inspect ------------------------------------------------------------------------

def run_inspect(capsys, *args):
    status = inspect_tool.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.mark.parametrize('params', [ANKLE, KNEE], ids=['ankle', 'knee'])
def test_inspect_draws_both_spaces_and_the_transmission(tmp_path, capsys, params):
    pose, tmap = tmp_path / 'pose.png', tmp_path / 'map.png'
    status, out, err = run_inspect(capsys, '--params-file', params, '--plot', pose,
                                   '--transmission', tmap)
    assert status == 0, err
    for path in (pose, tmap):
        data = path.read_bytes()
        assert len(data) > 10_000 and data[:8] == b'\x89PNG\r\n\x1a\n'
    assert 'joint space (what a controller commands)' in out
    assert 'transmission (J = dq/dtheta' in out and f'wrote {tmap}' in out


def test_the_picture_labels_both_spaces():
    from cog_id_ros.offline import mechanism_plot
    mech = cog_id_ros.Mechanism.from_params_file(str(ANKLE))
    fig = mechanism_plot.mechanism_figure(mech, mech.assembled_coordinates)
    labels = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
    assert any(label.startswith('actuator space') for label in labels)
    assert any(label.startswith('joint space') and 'ankle_pitch' in label for label in labels)


def test_the_knee_sweep_ends_at_its_toggle():
    from cog_id_ros.offline import transmission_plot
    mech = cog_id_ros.Mechanism.from_params_file(str(KNEE))
    (sweep,) = transmission_plot.sweep(cog_id_ros.Transmission(mech, 'python'))
    assert sweep.grid[-1] == pytest.approx(0.7714, abs=2e-3)   # the toggle
    assert set(sweep.stops) == {'upper', 'lower'}
    # J agrees with the ratio of position differences along the sweep
    tr = cog_id_ros.Transmission(mech)
    theta = np.array([tr.to_actuator_space([x])[0] for x in sweep.grid[40:43]])
    slope = (sweep.grid[42] - sweep.grid[40]) / (theta[2] - theta[0])
    assert sweep.jacobians[41, 0, 0] == pytest.approx(slope, rel=1e-3)


def test_transmission_without_joint_space_is_named(tmp_path, capsys):
    tmap = tmp_path / 'map.png'
    status, out, err = run_inspect(capsys, '--params-file', FOUR_BAR, '--transmission', tmap)
    assert status == 2 and 'mechanism.joint_space' in err
    assert not tmap.exists() and out == ''


def test_transmission_with_an_unknown_format_is_named(tmp_path, capsys):
    status, _, err = run_inspect(capsys, '--params-file', ANKLE, '--transmission',
                                 tmp_path / 'map.xyz')
    assert status == 2 and '--transmission' in err and "'xyz'" in err
