"""cog_id_simulate: its CSV contract, the hold rule, the initial state rules, and every bad
input ending in one line that names what to fix, with its exit status and no output file.

The tool runs in this process (``simulate.main``) where only its result matters, and as a
subprocess where a user's view does (a signal, the console script).
"""
import os
from pathlib import Path
import pty
import resource
import signal
import subprocess
import sys

import numpy as np
import pytest

from cog_id_ros.offline import simulate, simulate_inputs
from cog_id_ros.offline import trajectory_io as tio

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config'
PARAMS_A = CONFIG / 'paper_four_bar_a.yaml'
PARAMS_B = CONFIG / 'paper_four_bar_b.yaml'
TARGET = CONFIG / 'paper_four_bar_target.csv'
A_JOINTS = ['joint1', 'joint2', 'joint3', 'joint4']


def write_csv(path, columns):
    """columns: {name: 1-D array or list of cells}, numbers written with repr."""
    names = list(columns)
    cols = [[c if isinstance(c, str) else repr(float(c)) for c in columns[n]] for n in names]
    path.write_text(','.join(names) + '\n' + '\n'.join(map(','.join, zip(*cols))) + '\n')
    return path


def simulate_in_process(capsys, *args):
    """(status, stdout, stderr) of cog_id_simulate run in this process."""
    status = simulate.main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert 'Traceback' not in err, err
    return status, out, err


def read_motion(path):
    header, t, values = tio.read_efforts(path)      # a plain numeric CSV reader
    return header, t, values


def error_line(err):
    lines = [line for line in err.splitlines() if line.startswith('cog_id_simulate: error:')]
    assert len(lines) == 1, err
    return lines[0]


# --- the hold rule -----------------------------------------------------------------------

def test_each_row_holds_its_effort_until_the_next_row_bit_for_bit():
    t = np.array([0.0, 0.003, 0.004])
    efforts = np.array([[1.0, -1.0], [2.0, -2.0], [3.0, -3.0]])
    held, spanning = simulate_inputs.step_efforts(t, efforts, 0.001, simulate_inputs.step_count(t, 0.001))
    np.testing.assert_array_equal(held, [[1.0, -1.0]] * 3 + [[2.0, -2.0]])
    assert spanning == 0


def test_times_written_as_decimals_are_on_the_step_grid():
    """0.001 * k written by repr (0.003 is not 3 * 0.001 in doubles) is on the 1 ms grid:
    every step holds exactly its row's effort."""
    t = np.array([round(0.001 * k, 12) for k in range(1001)])
    efforts = np.arange(1001.0)[:, None]
    n = simulate_inputs.step_count(t, 0.001)
    assert n == 1000
    held, spanning = simulate_inputs.step_efforts(t, efforts, 0.001, n)
    np.testing.assert_array_equal(held[:, 0], np.arange(1000.0))
    assert spanning == 0


def test_a_step_that_spans_a_change_holds_the_time_average():
    t = np.array([0.0, 0.0015, 0.003])
    held, spanning = simulate_inputs.step_efforts(t, np.array([[1.0], [3.0], [5.0]]), 0.001, 3)
    np.testing.assert_allclose(held[:, 0], [1.0, 2.0, 3.0], rtol=1e-12)
    assert spanning == 1
    # rows closer than a step: the step holds their mean (the same impulse)
    fine = np.arange(9) * 0.00025
    held, spanning = simulate_inputs.step_efforts(fine, np.arange(9.0)[:, None], 0.001, 2)
    np.testing.assert_allclose(held[:, 0], [1.5, 5.5], rtol=1e-12)
    assert spanning == 2


def test_linear_holds_the_mean_of_the_line_between_samples():
    """--between-rows linear: on the step grid the mean of two neighbouring samples; off it
    (and across rows) the exact mean of the piecewise-linear effort over the step."""
    t = np.array([0.0, 0.001, 0.002, 0.003])
    e = np.array([[0.0], [2.0], [6.0], [6.0]])
    held, spanning = simulate_inputs.step_efforts(t, e, 0.001, 3, linear=True)
    np.testing.assert_allclose(held[:, 0], [1.0, 4.0, 6.0], rtol=1e-12)
    assert spanning == 0
    # a step of 1.5 ms over rows 1 ms apart: the mean of the line, by quadrature
    held, spanning = simulate_inputs.step_efforts(t, e, 0.0015, 2, linear=True)
    fine = np.linspace(0.0, 0.003, 300001)
    line = np.interp(fine, t, e[:, 0])
    expect = [line[fine <= 0.0015].mean(), line[fine >= 0.0015].mean()]
    np.testing.assert_allclose(held[:, 0], expect, rtol=1e-4)
    assert spanning == 2


def test_steps_end_at_or_before_the_last_input_time():
    assert simulate_inputs.step_count(np.array([0.0, 0.0025]), 0.001) == 2
    assert simulate_inputs.step_count(np.array([5.0]), 0.001) == 0
    assert simulate_inputs.step_count(np.array([0.1, 0.4]), 0.1) == 3     # 0.3 / 0.1 = 2.9999...


# --- errors that name what to fix -----------------------------------------------------------

def efforts_file(tmp_path, **columns):
    base = {'time': [0.0, 0.001, 0.002], 'joint3.effort': [1.0, 1.0, 1.0]}
    base.update(columns)
    return write_csv(tmp_path / 'efforts.csv', {k: v for k, v in base.items() if v is not None})


BAD_INPUTS = [
    (dict(**{'joint3.effort': None, 'joint3.torque': [1.0, 1.0, 1.0]}),
     "missing column 'joint3.effort' (the effort of active joint joint3)"),
    (dict(**{'jointX.effort': [1.0, 1.0, 1.0]}), "unknown joint 'jointX'"),
    (dict(**{'joint3.effort': ['1.0', 'abc', '1.0']}),
     "row 2 (line 3 of the file), column 'joint3.effort': 'abc' is not a number"),
    (dict(**{'joint3.effort': ['1.0', '1.0', 'nan']}), 'NaN is not allowed'),
    (dict(time=[0.0, 0.002, 0.001]), 'does not increase strictly'),
    (dict(**{'joint3.effort': ['1.0', '', '1.0']}),
     'cog_id_torques --skip-invalid leaves the efforts of a row it could not solve empty'),
    (dict(**{'joint3.velocity': ['', '', '']}), "column 'joint3.velocity': empty cell"),
    (dict(**{'joint3.position': ['1e999', '', '']}), 'beyond the range of a double'),
]


@pytest.mark.parametrize('columns, words', BAD_INPUTS)
def test_a_bad_efforts_file_is_one_line_with_status_1_and_no_output(tmp_path, capsys, columns,
                                                                     words):
    src = efforts_file(tmp_path, **columns)
    status, out, err = simulate_in_process(
        capsys, '--params-file', PARAMS_A, '--input', src, '--output', tmp_path / 'm.csv')
    assert status == 1
    assert words in error_line(err)
    assert str(src) in error_line(err)
    assert sorted(os.listdir(tmp_path)) == ['efforts.csv'] and out == ''


def test_an_initial_state_of_some_active_joints_only_is_named(tmp_path, capsys):
    src = write_csv(tmp_path / 'efforts.csv', {
        'time': [0.0, 0.001], 'joint1.effort': [0.0, 0.0], 'joint3.effort': [0.0, 0.0],
        'joint1.position': [1.5, 1.5]})
    status, _, err = simulate_in_process(
        capsys, '--params-file', PARAMS_B, '--input', src, '--output', tmp_path / 'm.csv')
    assert status == 1
    assert ('has joint1.position but not joint3.position: the initial state needs the '
            'position of every active joint (or of none)') in error_line(err)


@pytest.mark.parametrize('args, words', [
    (['--time-step', '0'], 'argument --time-step: must be > 0 and at most 1 s'),
    (['--time-step', 'nan'], 'argument --time-step: must be > 0'),
    (['--time-step', '2'], 'at most 1 s'),
    (['--time-step', 'abc'], "not a number: 'abc'"),
])
def test_a_bad_time_step_is_a_usage_error(tmp_path, capsys, args, words):
    with pytest.raises(SystemExit) as stop:
        simulate.main(['--params-file', str(PARAMS_A), '--input', str(efforts_file(tmp_path)),
                       '--output', str(tmp_path / 'm.csv')] + args)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and words in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize('option, value, words', [
    ('--initial-state', 'nowhere.csv', '--initial-state nowhere.csv: no such file'),
    ('--reference', 'nowhere.csv', '--reference nowhere.csv: no such file'),
    ('--plot', 'm.xyz', "--plot m.xyz: unknown image format 'xyz'"),
    ('--output', 'efforts.csv', '--output efforts.csv: is the input file'),
])
def test_bad_paths_are_one_line_with_status_2(tmp_path, capsys, monkeypatch, option, value,
                                              words):
    efforts_file(tmp_path)
    monkeypatch.chdir(tmp_path)
    args = {'--params-file': str(PARAMS_A), '--input': 'efforts.csv', '--output': 'm.csv',
            option: value}
    status, _, err = simulate_in_process(capsys, *[x for kv in args.items() for x in kv])
    assert status == 2 and words in error_line(err)
    assert sorted(os.listdir(tmp_path)) == ['efforts.csv']


def test_a_missing_parameter_file_is_status_3(tmp_path, capsys):
    status, _, err = simulate_in_process(
        capsys, '--params-file', tmp_path / 'none.yaml', '--input', efforts_file(tmp_path),
        '--output', tmp_path / 'm.csv')
    assert status == 3 and 'no such file' in error_line(err)


def test_too_many_steps_are_refused_before_any_work(tmp_path, capsys):
    src = efforts_file(tmp_path, time=[0.0, 1.0, 1e6])
    status, _, err = simulate_in_process(capsys, '--params-file', PARAMS_A, '--input', src,
                                         '--output', tmp_path / 'm.csv', '--time-step', '1e-3')
    assert status == 2
    assert 'more than 100,000,000: use a larger --time-step or split the input' in err


def test_help_names_the_contract_and_the_statuses(capsys):
    with pytest.raises(SystemExit):
        simulate.main(['--help'])
    text = capsys.readouterr().out
    for words in ('acts from time[i] until time[i+1]', 'initial_positions, at rest',
                  '--initial-state', '--reference', 'one row per step', '130 Ctrl-C',
                  'exit status'):
        assert words in text, words


def test_the_console_script_is_installed():
    script = Path(sys.executable).parent / 'cog_id_simulate'
    assert script.exists()
    proc = subprocess.run([str(script), '--help'], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and 'cog_id_simulate' in proc.stdout


# --- the simulation stops, and says where ------------------------------------------------------

SHORT_COUPLER = (ROOT / 'test' / 'offline' / 'test_cli.py').read_text().split(
    'SHORT_COUPLER = """\\\n')[1].split('"""')[0]


def test_a_loop_that_cannot_close_on_the_way_stops_the_run_with_the_step_row_and_time(
        tmp_path, capsys):
    """The short-coupler four-bar pushed beyond joint1 = 1.287 rad, where its loop cannot
    close: status 1, one line naming the step, the input row whose efforts it held, the time
    and the joint; no output."""
    params = tmp_path / 'short.yaml'
    params.write_text(SHORT_COUPLER)
    src = write_csv(tmp_path / 'push.csv', {'time': [0.0, 0.1, 2.0],
                                            'joint1.effort': [20.0, 20.0, 20.0]})
    status, out, err = simulate_in_process(capsys, '--params-file', params, '--input', src,
                                           '--output', tmp_path / 'm.csv')
    line = error_line(err)
    assert status == 1 and out == ''
    assert 'push.csv: step 129 (the efforts of row 2, line 3 of the file): simulation stopped ' \
           'at t = 0.129 s' in line
    assert 'joint1 = 1.28' in line and 'cannot be closed' in line
    assert sorted(os.listdir(tmp_path)) == ['push.csv', 'short.yaml']


def test_efforts_too_large_to_compute_with_stop_the_run(tmp_path, capsys):
    src = efforts_file(tmp_path, **{'joint3.effort': [1e300, 1e300, 1e300]})
    status, _, err = simulate_in_process(capsys, '--params-file', PARAMS_A, '--input', src,
                                         '--output', tmp_path / 'm.csv')
    assert status == 1 and 'step 1 (the efforts of row 1' in error_line(err)
    assert 'too large' in error_line(err)
    assert sorted(os.listdir(tmp_path)) == ['efforts.csv']


def test_one_row_gives_the_initial_state_alone(tmp_path, capsys):
    src = write_csv(tmp_path / 'one.csv', {'time': [5.0], 'joint3.effort': [1.0]})
    status, out, _ = simulate_in_process(capsys, '--params-file', PARAMS_A, '--input', src,
                                         '--output', tmp_path / 'm.csv')
    header, t, values = read_motion(tmp_path / 'm.csv')
    assert status == 0 and t.tolist() == [5.0] and values.shape == (1, 8)
    assert '0 steps of 0.001 s, t = 5 .. 5 s' in out


def test_progress_bar_on_a_terminal_only(tmp_path):
    """12,000 steps: drawn on a terminal every 1,000 steps, never into a pipe."""
    src = write_csv(tmp_path / 'long.csv', {'time': [0.0, 12.0], 'joint3.effort': [0.0, 0.0]})
    script = Path(sys.executable).parent / 'cog_id_simulate'
    args = [str(script), '--params-file', str(PARAMS_A), '--input', str(src), '--output',
            'm.csv']
    piped = subprocess.run(args, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert piped.returncode == 0 and '\r' not in piped.stderr, piped.stderr
    master, slave = pty.openpty()
    try:
        proc = subprocess.Popen(args, cwd=tmp_path, stdout=subprocess.PIPE, stderr=slave)
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
    assert 'simulating [' in tty and '\r' in tty
    assert '1,000/12,000 steps' in tty and '100% 12,000/12,000 steps' in tty


def _limit_file_size(limit):
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)     # EFBIG instead of a kill
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.mark.parametrize('option, path, limit', [('--output', 'm.csv', 100),
                                                 ('--plot', 'm.png', 8000)])
def test_a_write_error_names_the_users_path(tmp_path, option, path, limit):
    """Exit 4, the option and the path as given (never the temporary file), nothing left.
    (Files are limited to ``limit`` bytes: 21 rows of motion take ~4,000, the plot more.)"""
    (tmp_path / 'in').mkdir()
    (tmp_path / 'out').mkdir()
    src = write_csv(tmp_path / 'in' / 'e.csv', {'time': np.arange(21) * 0.001,
                                                'joint3.effort': np.zeros(21)})
    script = Path(sys.executable).parent / 'cog_id_simulate'
    proc = subprocess.run([str(script), '--params-file', str(PARAMS_A), '--input', str(src),
                           '--output', 'm.csv', '--plot', 'm.png'], cwd=tmp_path / 'out',
                          text=True, capture_output=True, timeout=300,
                          preexec_fn=_limit_file_size(limit))
    assert proc.returncode == 4, proc.stderr
    line = error_line(proc.stderr)
    assert f'{option} {path}: cannot write: File too large' in line and '.tmp' not in line
    assert os.listdir(tmp_path / 'out') == []
