"""cog_id_torques run as a user runs it: a subprocess on files in a temporary directory.

The outputs are checked against the core API on the same samples, against the paper
four-bar's exact torque, and for every bad input against the exit status, the one-line
message (row and column) and the absence of any output file.
"""
import json
import math
import os
from pathlib import Path
import pty
import shutil
import subprocess
import sys

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.offline import samples
from cog_id_ros.offline import trajectory_io as tio

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config'
PARAMS_A = CONFIG / 'paper_four_bar_a.yaml'
PARAMS_B = CONFIG / 'paper_four_bar_b.yaml'
TARGET = CONFIG / 'paper_four_bar_target.csv'
M, L, G = 1.0, 0.5, 9.81

# A four-bar whose coupler and rocker (0.3 m) are too short for the crank (0.5 m) beyond
# joint1 = 2 asin(0.6) = 1.287 rad: there the loop cannot close.
SHORT_COUPLER = """\
/**:
  ros__parameters:
    mechanism:
      name: short_coupler_four_bar
      gravity: [0.0, -9.81, 0.0]
      links: [link1, link2, link3]
      joints: [joint1, joint2, joint3, joint4]
      active_joints: [joint1]
      initial_positions: [0.8, -1.1064, 1.1059, 1.4123]
    links:
      link1: {mass: 1.0, com: [0.25, 0.0, 0.0], inertia: [0.0, 0.02, 0.02, 0.0, 0.0, 0.0]}
      link2: {mass: 0.5, com: [0.15, 0.0, 0.0], inertia: [0.0, 0.004, 0.004, 0.0, 0.0, 0.0]}
      link3: {mass: 0.5, com: [0.15, 0.0, 0.0], inertia: [0.0, 0.004, 0.004, 0.0, 0.0, 0.0]}
    joints:
      joint1: {type: revolute, parent: ground, child: link1}
      joint2: {type: revolute, parent: link1, child: link2, parent_xyz: [0.5, 0.0, 0.0]}
      joint3: {type: revolute, parent: ground, child: link3, parent_xyz: [0.5, 0.0, 0.0]}
      joint4: {type: revolute, parent: link2, child: link3, parent_xyz: [0.3, 0.0, 0.0],
               child_xyz: [0.3, 0.0, 0.0]}
"""


def tool_command():
    """The installed console script (as a user has it), else the module."""
    script = Path(sys.executable).parent / 'cog_id_torques'
    if script.exists():
        return [str(script)]
    found = shutil.which('cog_id_torques')
    return [found] if found else [sys.executable, '-m', 'cog_id_ros.offline.cli']


def run_tool(*args, cwd, stderr=subprocess.PIPE):
    return subprocess.run(tool_command() + [str(a) for a in args], cwd=cwd, text=True,
                          stdout=subprocess.PIPE, stderr=stderr, timeout=300)


def exact_torque_a(theta, theta_ddot):
    """Paper four-bar (a), our reading: tau3 = (5/3) m L^2 thetaddot + 2 m g L cos(theta)."""
    return 5.0 / 3.0 * M * L * L * theta_ddot + 2.0 * M * G * L * np.cos(theta)


def write_csv(path, columns):
    """columns: {name: 1-D array}, written with repr (full precision)."""
    names = list(columns)
    cols = [list(map(repr, np.asarray(columns[n], dtype=float).tolist())) for n in names]
    path.write_text(','.join(names) + '\n' + '\n'.join(map(','.join, zip(*cols))) + '\n')
    return path


def target(t):
    w = math.pi
    return (math.pi / 2 + 0.5 * np.sin(w * t), 0.5 * w * np.cos(w * t),
            -0.5 * w * w * np.sin(w * t))


def core_torques(params, input_csv, on_invalid=None):
    """The core API's torques on the same samples (fresh solver, one batch call)."""
    mech = cog_id_ros.Mechanism.from_params_file(str(params))
    traj = tio.read_trajectory(input_csv, mech.joints, mech.active_joints)
    q, qd, qdd, _ = samples.setpoints(traj, mech.active_joints)
    solver = cog_id_ros.InverseDynamics(mech)
    if on_invalid is None:
        return traj.time, q, qd, solver.torques(q, qd, qdd)
    return traj.time, q, qd, solver.evaluate(q, qd, qdd, on_invalid=on_invalid)


def error_lines(proc):
    assert 'Traceback' not in proc.stderr, proc.stderr
    return [line for line in proc.stderr.splitlines() if line.startswith('cog_id_torques: error:')]


# --- results ---------------------------------------------------------------------------------

def test_target_motion_a_equals_the_core_and_the_exact_torque(tmp_path):
    proc = run_tool('--params-file', PARAMS_A, '--input', TARGET, '--output', 'tau.csv',
                    cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    header, t, tau = tio.read_efforts(tmp_path / 'tau.csv')
    assert header == ['time', 'joint3.effort']
    time, q, qd, ref = core_torques(PARAMS_A, TARGET)
    np.testing.assert_array_equal(t, time)
    np.testing.assert_array_equal(tau, ref)          # same samples, same numbers
    theta, _, theta_ddot = target(time)
    np.testing.assert_allclose(tau[:, 0], exact_torque_a(theta, theta_ddot), rtol=0, atol=1e-9)
    # the file has joint1 columns too (for (b)): ignored with a note, not an error
    assert 'note:' in proc.stderr and 'joint1.position' in proc.stderr


@pytest.mark.parametrize('backend', ['python', 'reference'])
def test_the_backend_can_be_chosen_and_changes_no_number(tmp_path, backend):
    """--backend: native off (python) or the plain lane code give the same file."""
    for name, option in (('auto.csv', ()), (f'{backend}.csv', ('--backend', backend))):
        proc = run_tool('--params-file', PARAMS_A, '--input', TARGET, '--output', name,
                        *option, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
    assert (tmp_path / 'auto.csv').read_text() == (tmp_path / f'{backend}.csv').read_text()
    proc = run_tool('--params-file', PARAMS_A, '--input', TARGET, '--output', 'x.csv',
                    '--backend', 'fast', cwd=tmp_path)
    assert proc.returncode != 0 and 'backend' in proc.stderr


def test_target_motion_b_equals_the_core_and_splits_the_exact_torque(tmp_path):
    proc = run_tool('--params-file', PARAMS_B, '--input', TARGET, '--output', 'tau.csv',
                    cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    header, t, tau = tio.read_efforts(tmp_path / 'tau.csv')
    assert header == ['time', 'joint1.effort', 'joint3.effort']
    time, q, qd, ref = core_torques(PARAMS_B, TARGET)
    np.testing.assert_array_equal(tau, ref)
    theta, _, theta_ddot = target(time)
    # two equal cranks of a parallelogram share the single-actuator torque (minimum norm)
    np.testing.assert_allclose(tau.sum(axis=1), exact_torque_a(theta, theta_ddot), atol=1e-9)
    np.testing.assert_allclose(tau[:, 0], tau[:, 1], atol=1e-9)


def test_positions_only_on_uneven_steps_equal_the_core_on_the_estimates(tmp_path):
    rng = np.random.default_rng(11)
    t = np.concatenate([[0.0], np.cumsum(0.002 * (0.5 + rng.random(999)))])  # steps 1..3 ms
    theta, _, theta_ddot = target(t)
    src = write_csv(tmp_path / 'traj.csv', {'time': t, 'joint3.position': theta})
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv',
                    cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert 'estimating joint3.velocity, joint3.acceleration' in proc.stderr
    _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
    _, _, _, ref = core_torques(PARAMS_A, src)
    np.testing.assert_array_equal(tau, ref)
    np.testing.assert_allclose(tau[:, 0], exact_torque_a(theta, theta_ddot), atol=1e-4)


def test_estimated_derivatives_converge_at_the_stated_order_through_the_tool(tmp_path):
    # positions only, uneven steps (a tiled random pattern, halved each time): the torque
    # error of (a) is (5/3) m L^2 times the acceleration error, stated O(h^3)
    pattern = 0.5 + np.random.default_rng(5).random(8)
    hs, errs = [], []
    for n in (64, 128, 256):
        steps = np.tile(pattern, n // pattern.size) * (2.0 / n)
        t = np.concatenate([[0.0], np.cumsum(steps)])
        theta, _, theta_ddot = target(t)
        src = write_csv(tmp_path / f'traj{n}.csv', {'time': t, 'joint3.position': theta})
        proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', f'tau{n}.csv',
                        cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        _, _, tau = tio.read_efforts(tmp_path / f'tau{n}.csv')
        hs.append(steps.max())
        errs.append(np.max(np.abs(tau[:, 0] - exact_torque_a(theta, theta_ddot))))
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert slope == pytest.approx(3.0, abs=0.3), (hs, errs)


def test_json_summary_matches_the_output(tmp_path):
    proc = run_tool('--params-file', PARAMS_B, '--input', TARGET, '--output', 'tau.csv',
                    '--json', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s['mechanism'] == 'paper_four_bar_b'
    assert s['samples'] == s['solved'] == 2001 and s['skipped'] == 0 and s['skipped_rows'] == []
    assert s['active_joints'] == ['joint1', 'joint3']
    assert s['estimated_columns'] == [] and s['time_start'] == 0.0 and s['time_end'] == 2.0
    _, t, tau = tio.read_efforts(tmp_path / 'tau.csv')
    _, _, qd, _ = core_torques(PARAMS_B, TARGET)
    for k, j in enumerate(s['joints']):
        assert j['joint'] == s['active_joints'][k] and j['unit'] == 'N m'
        e, p = tau[:, k], tau[:, k] * qd[:, k]
        assert j['peak_effort'] == np.max(np.abs(e))
        assert abs(e[j['peak_effort_row'] - 1]) == j['peak_effort']       # rows count from 1
        assert j['peak_effort_time'] == t[j['peak_effort_row'] - 1]
        assert j['rms_effort'] == pytest.approx(np.sqrt(np.mean(e ** 2)), rel=1e-12)
        assert j['peak_power'] == pytest.approx(np.max(np.abs(p)), rel=1e-12)
        assert abs(p[j['peak_power_row'] - 1]) == pytest.approx(j['peak_power'], rel=1e-12)
    # paper (a) peak 6.7593 N m at t = 0.5 s, shared equally by the two cranks of (b)
    assert s['joints'][0]['peak_effort'] == pytest.approx(6.75933 / 2, abs=1e-5)


def test_text_summary_and_plot(tmp_path):
    proc = run_tool('--params-file', PARAMS_A, '--input', TARGET, '--output', 'tau.csv',
                    '--plot', 'tau.png', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert out.startswith('paper_four_bar_a: 2,001 samples')
    row = [line for line in out.splitlines() if line.startswith('joint3')][0]
    assert '6.75933 N m' in row and 'row 501 (t = 0.5 s)' in row    # peak |tau|, where
    assert '4.81395 N m' in row and ' W ' in row                     # RMS, peak power
    png = (tmp_path / 'tau.png').read_bytes()
    assert png[:8] == b'\x89PNG\r\n\x1a\n' and len(png) > 20_000
    assert sorted(os.listdir(tmp_path)) == ['tau.csv', 'tau.png']


# --- bad input ---------------------------------------------------------------------------------

def _case_files(tmp_path, case):
    """(params, input file, expected row, expected text) for one bad-input case."""
    t = np.arange(12) * 0.01
    theta = 1.5 + 0.1 * t
    good = {'time': t, 'joint3.position': theta, 'joint3.velocity': np.full(12, 0.1),
            'joint3.acceleration': np.zeros(12)}
    src = tmp_path / 'traj.csv'
    if case == 'missing column':
        write_csv(src, {'time': t, 'joint3.velocity': good['joint3.velocity']})
        return PARAMS_A, src, None, "header (line 1 of the file), column 'joint3.position': missing column"
    if case == 'unknown joint':
        write_csv(src, {**good, 'jointX.position': theta})
        return PARAMS_A, src, None, "column 'jointX.position': unknown joint 'jointX'"
    write_csv(src, good)
    lines = src.read_text().splitlines()
    if case == 'non-numeric cell':
        lines[7] = lines[7].replace(lines[7].split(',')[2], 'fast', 1)
        src.write_text('\n'.join(lines) + '\n')
        return PARAMS_A, src, 7, "row 7 (line 8 of the file), column 'joint3.velocity': 'fast' is not a number"
    if case == 'NaN':
        cells = lines[5].split(',')
        cells[1] = 'nan'
        lines[5] = ','.join(cells)
        src.write_text('\n'.join(lines) + '\n')
        return PARAMS_A, src, 5, "row 5 (line 6 of the file), column 'joint3.position': NaN"
    if case == 'time not increasing':
        lines[9], lines[10] = lines[10], lines[9]
        src.write_text('\n'.join(lines) + '\n')
        return PARAMS_A, src, 10, "row 10 (line 11 of the file), column 'time': time 0.08"
    if case == 'loop cannot close':
        params = tmp_path / 'short.yaml'
        params.write_text(SHORT_COUPLER)
        q = np.linspace(0.8, 1.5, 15)             # closes up to 1.287 rad: rows 1..10
        write_csv(src, {'time': np.arange(15) * 0.1, 'joint1.position': q,
                        'joint1.velocity': np.zeros(15), 'joint1.acceleration': np.zeros(15)})
        # the wording is the core's ('the loops cannot be closed', or 'cannot reach the
        # setpoint' when the continuation stops): the row and the column are the tool's
        return params, src, 11, "row 11 (line 12 of the file), column(s) 'joint1.position': "
    if case == 'singular pose':
        q = np.array([1.5, 1.0, 0.5, 0.0, 0.5])    # the parallelogram folds flat at 0 rad
        write_csv(src, {'time': np.arange(5) * 0.1, 'joint3.position': q,
                        'joint3.velocity': np.zeros(5), 'joint3.acceleration': np.zeros(5)})
        return PARAMS_A, src, 4, "row 4 (line 5 of the file), column(s) 'joint3.position': singular"
    raise ValueError(case)


BAD_CASES = ['missing column', 'non-numeric cell', 'NaN', 'time not increasing',
             'loop cannot close', 'singular pose', 'unknown joint']


@pytest.mark.parametrize('case', BAD_CASES)
def test_bad_input_exits_non_zero_with_one_line_and_no_output(tmp_path, case):
    params, src, row, text = _case_files(tmp_path, case)
    before = sorted(os.listdir(tmp_path))
    proc = run_tool('--params-file', params, '--input', src, '--output', 'tau.csv',
                    '--plot', 'tau.png', cwd=tmp_path)
    assert proc.returncode == 1
    errors = error_lines(proc)
    assert len(errors) == 1, proc.stderr
    assert text in errors[0], errors[0]
    assert str(src) in errors[0]
    assert sorted(os.listdir(tmp_path)) == before      # no output, no temporary left behind
    assert proc.stdout == ''


def test_a_failed_run_keeps_an_older_output(tmp_path):
    params, src, _, _ = _case_files(tmp_path, 'loop cannot close')
    (tmp_path / 'tau.csv').write_text('from an earlier run\n')
    proc = run_tool('--params-file', params, '--input', src, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 1
    assert (tmp_path / 'tau.csv').read_text() == 'from an earlier run\n'
    assert len(os.listdir(tmp_path)) == 3


def test_skip_invalid_reports_the_rows_and_leaves_their_cells_empty(tmp_path):
    params, src, _, _ = _case_files(tmp_path, 'loop cannot close')
    proc = run_tool('--params-file', params, '--input', src, '--output', 'tau.csv',
                    '--skip-invalid', '--json', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s['skipped_rows'] == [11, 12, 13, 14, 15] and s['solved'] == 10
    # keyed by the core's machine-readable reason; the exception types are kept apart
    assert set(s['skipped_reasons']) <= {'closure', 'unreachable'}
    assert sum(s['skipped_reasons'].values()) == 5
    assert s['skipped_error_types'] == {'ClosureError': 5}
    assert set(s['skipped_row_reasons']) == set(s['skipped_reasons'])
    for row in s['skipped_rows']:
        assert f'row {row} (line {row + 1} of the file): ' in proc.stderr
    lines = (tmp_path / 'tau.csv').read_text().splitlines()
    assert all(line.endswith(',') for line in lines[11:]) and len(lines) == 16
    _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
    _, _, _, ev = core_torques(params, src, on_invalid='skip')
    assert ev.valid.tolist() == [True] * 10 + [False] * 5
    np.testing.assert_array_equal(tau[:10], ev.torques[:10])


def test_skip_invalid_skips_a_singular_row(tmp_path):
    params, src, _, _ = _case_files(tmp_path, 'singular pose')
    proc = run_tool('--params-file', params, '--input', src, '--output', 'tau.csv',
                    '--skip-invalid', '--plot', 'tau.png', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert 'row 4 (line 5 of the file): singular configuration' in proc.stderr
    _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
    assert np.isnan(tau[3, 0]) and np.isfinite(np.delete(tau[:, 0], 3)).all()
    assert (tmp_path / 'tau.png').exists()
    assert '1 skipped' in proc.stdout


def test_a_bad_parameter_file_names_the_parameter(tmp_path):
    params = tmp_path / 'bad.yaml'
    params.write_text(PARAMS_A.read_text().replace('mass: 1.0', 'mass: -1.0', 1))
    proc = run_tool('--params-file', params, '--input', TARGET, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 3
    [line] = error_lines(proc)
    assert 'links.link1.mass' in line and str(params) in line
    assert sorted(os.listdir(tmp_path)) == ['bad.yaml']


@pytest.mark.parametrize('args, words', [
    (['--input', 'missing.csv', '--output', 'tau.csv'], '--input missing.csv: no such file'),
    (['--input', str(TARGET), '--output', 'no/such/dir/tau.csv'], 'does not exist'),
    (['--input', str(TARGET), '--output', 'tau.csv', '--plot', 'tau.xyz'], "unknown image format 'xyz'"),
])
def test_command_line_errors_exit_2_before_any_work(tmp_path, args, words):
    proc = run_tool('--params-file', PARAMS_A, *args, cwd=tmp_path)
    assert proc.returncode == 2
    [line] = error_lines(proc)
    assert words in line
    assert os.listdir(tmp_path) == []


# --- progress, chunking, packaging ---------------------------------------------------------------

def _long_input(tmp_path, n=12_000):
    t = np.arange(n) * 1e-3
    return write_csv(tmp_path / 'long.csv', {'time': t, 'joint3.position': target(t)[0]})


def test_progress_bar_on_a_terminal_only(tmp_path):
    src = _long_input(tmp_path)
    args = ['--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', '--chunk-size', 5000]
    piped = run_tool(*args, cwd=tmp_path)
    assert piped.returncode == 0 and '\r' not in piped.stderr and '[' not in piped.stderr
    master, slave = pty.openpty()
    try:
        proc = subprocess.Popen(tool_command() + [str(a) for a in args], cwd=tmp_path,
                                stdout=subprocess.PIPE, stderr=slave)
        os.close(slave)
        chunks = []
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:        # EIO: the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        proc.stdout.read()
        proc.stdout.close()
        assert proc.wait(timeout=300) == 0
    finally:
        os.close(master)
    tty = b''.join(chunks).decode()
    assert 'solving [' in tty and '\r' in tty
    assert '5,000/12,000 samples' in tty and '100% 12,000/12,000 samples' in tty
    # and no bar for inputs of up to 10,000 samples, even on a terminal: see ProgressBar.wanted
    from cog_id_ros.offline.progress import ProgressBar

    class Tty:
        def isatty(self):
            return True
    assert not ProgressBar.wanted(10_000, Tty()) and ProgressBar.wanted(10_001, Tty())
    assert not ProgressBar.wanted(10_001, Tty(), disabled=True)


def test_chunk_size_changes_nothing_beyond_the_closure_tolerance(tmp_path):
    for chunk in (7, 100_000):
        proc = run_tool('--params-file', PARAMS_B, '--input', TARGET, '--output',
                        f'tau{chunk}.csv', '--chunk-size', chunk, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
    _, t7, a = tio.read_efforts(tmp_path / 'tau7.csv')
    _, t1, b = tio.read_efforts(tmp_path / 'tau100000.csv')
    np.testing.assert_array_equal(t7, t1)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_runs_without_rclpy(tmp_path):
    code = ('import sys; sys.modules["rclpy"] = None\n'
            'from cog_id_ros.offline.cli import main\n'
            f'status = main(["--params-file", {str(PARAMS_A)!r}, "--input", {str(TARGET)!r},'
            ' "--output", "tau.csv", "--plot", "tau.png"])\n'
            'assert not any(m.startswith("rclpy") and sys.modules[m] is not None for m in sys.modules)\n'
            'sys.exit(status)\n')
    proc = subprocess.run([sys.executable, '-c', code], cwd=tmp_path, text=True,
                          capture_output=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / 'tau.csv').exists()


def test_help_documents_the_scheme_rows_and_statuses(tmp_path):
    proc = run_tool('--help', cwd=tmp_path)
    assert proc.returncode == 0
    text = ' '.join(proc.stdout.split())
    for words in ('--params-file', '--skip-invalid', '--json', 'Fornberg', 'O(h^4)', 'O(h^3)',
                  'row r is line r+1 of the file', 'exit status', '<joint>.position'):
        assert words in text, words


def test_shipped_target_trajectory_is_the_paper_motion(tmp_path):
    out = tmp_path / 'target.csv'
    subprocess.run([sys.executable, '-m', 'cog_id_ros.demos.paper_four_bar', '--output', str(out)],
                   check=True, capture_output=True, timeout=120)
    assert out.read_bytes() == TARGET.read_bytes()    # the kept generator makes the shipped file
    traj = tio.read_trajectory(TARGET, ['joint1', 'joint2', 'joint3', 'joint4'], ['joint1', 'joint3'])
    assert len(traj) == 2001 and traj.time[0] == 0.0 and traj.time[-1] == 2.0
    np.testing.assert_allclose(np.diff(traj.time), 1e-3, rtol=1e-9)
    for j in ('joint1', 'joint3'):
        theta, dtheta, ddtheta = target(traj.time)
        np.testing.assert_allclose(traj.columns[f'{j}.position'], theta, atol=1e-15)
        np.testing.assert_allclose(traj.columns[f'{j}.velocity'], dtheta, atol=1e-14)
        np.testing.assert_allclose(traj.columns[f'{j}.acceleration'], ddtheta, atol=1e-13)


def test_a_column_of_a_joint_without_coordinate_is_ignored_not_unknown(tmp_path):
    """A universal or spherical joint is a joint of the mechanism: its column is ignored
    with the note every passive joint's gets, not refused as an unknown joint."""
    t = np.arange(5) * 0.001
    csv = write_csv(tmp_path / 'in.csv', {
        'time': t, **{f'l{i}_p.position': 0.1325576213264454 + 0.0 * t for i in range(6)},
        'l0_u.position': 0.0 * t})
    proc = run_tool('--params-file', CONFIG / 'stewart_6ups_spherical.yaml', '--input', csv,
                    '--output', tmp_path / 'out.csv', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert 'ignoring l0_u.position: not an active joint' in proc.stderr, proc.stderr
