"""cog_id_simulate's columns as cog_id_torques reads them, and its messages in plain numbers.

Issue (low): an efforts CSV with a column of an unknown joint that the tool does not read
(``jointX.acceleration``) ran with a note and exit status 0, where docs/cli.md lists an
unknown column as exit status 1 and cog_id_torques refuses such a column (most likely a
joint's name mistyped); and the tool's messages printed numpy's reprs
(``--initial-state starts at t = np.float64(0.5) s``).
"""
import os
from pathlib import Path
import re

import pytest

from cog_id_ros.offline import simulate

ROOT = Path(__file__).resolve().parents[2]
PARAMS_A = ROOT / 'config' / 'paper_four_bar_a.yaml'


def write_csv(path, columns):
    names = list(columns)
    cols = [[repr(float(c)) for c in columns[n]] for n in names]
    path.write_text(','.join(names) + '\n' + '\n'.join(map(','.join, zip(*cols))) + '\n')
    return path


def efforts(tmp_path, **extra):
    columns = {'time': [0.0, 0.001, 0.002], 'joint3.effort': [0.0, 0.0, 0.0]}
    columns.update(extra)
    return write_csv(tmp_path / 'efforts.csv', columns)


def run(capsys, tmp_path, src, *more):
    status = simulate.main(['--params-file', str(PARAMS_A), '--input', str(src), '--output',
                            str(tmp_path / 'motion.csv'), *map(str, more)])
    out, err = capsys.readouterr()
    assert 'Traceback' not in err and 'np.' not in err and 'np.' not in out, err
    return status, out, err


def error_line(err):
    lines = [line for line in err.splitlines() if line.startswith('cog_id_simulate: error:')]
    assert len(lines) == 1 and len(err.strip().splitlines()) == 1, err
    return lines[0]


@pytest.mark.parametrize('column', ['jointX.acceleration', 'jiont3.velocity', 'joint9.effort'])
def test_a_column_of_an_unknown_joint_is_status_1_naming_it(tmp_path, capsys, column):
    """As cog_id_torques: ``<name>.<field>`` of an unknown ``<name>`` is an error, whether
    or not the tool reads that field."""
    src = efforts(tmp_path, **{column: [0.0, 0.0, 0.0]})
    status, out, err = run(capsys, tmp_path, src)
    joint = column.split('.')[0]
    line = error_line(err)
    assert status == 1 and out == ''
    assert f"column '{column}': unknown joint '{joint}' in column 3" in line, line
    assert "the mechanism's joints are joint1, joint2, joint3, joint4" in line
    assert str(src) in line
    assert sorted(os.listdir(tmp_path)) == ['efforts.csv']


@pytest.mark.parametrize('option', ['--initial-state', '--reference'])
def test_a_column_of_an_unknown_joint_in_the_other_inputs_is_status_1(tmp_path, capsys,
                                                                       option):
    src = efforts(tmp_path)
    other = write_csv(tmp_path / 'state.csv', {'time': [0.0, 0.001, 0.002],
                                               'joint3.position': [1.5708] * 3,
                                               'jointX.effort': [0.0] * 3})
    status, _, err = run(capsys, tmp_path, src, option, other)
    line = error_line(err)
    assert status == 1
    assert line.startswith(f'cog_id_simulate: error: {option} {other}: header')
    assert "unknown joint 'jointX'" in line


def test_other_columns_are_ignored_with_a_note_as_cog_id_torques_does(tmp_path, capsys):
    """A column that names no joint field, and a known joint's column the tool does not
    read, are notes (docs/cli.md), exit status 0."""
    src = efforts(tmp_path, label=[1.0, 2.0, 3.0], **{'joint1.acceleration': [0.0] * 3})
    status, _, err = run(capsys, tmp_path, src)
    assert status == 0, err
    notes = [line for line in err.splitlines() if line.startswith('cog_id_simulate: note:')]
    assert any('label' in note and 'joint1.acceleration' in note for note in notes), err


def test_the_initial_state_note_prints_plain_numbers(tmp_path, capsys):
    src = efforts(tmp_path)
    state = write_csv(tmp_path / 'state.csv', {'time': [0.5, 0.501, 0.502],
                                               'joint3.position': [1.5708] * 3,
                                               'joint3.velocity': [0.0] * 3,
                                               'joint3.acceleration': [0.0] * 3})
    status, _, err = run(capsys, tmp_path, src, '--initial-state', state)
    assert status == 0, err
    assert ('note: --initial-state starts at t = 0.5 s, --input at t = 0.0 s: the state of '
            'its first row is taken as the state at the first input time') in err, err


def test_a_reference_that_does_not_overlap_prints_plain_numbers(tmp_path, capsys):
    src = efforts(tmp_path)
    ref = write_csv(tmp_path / 'ref.csv', {'time': [10.0, 11.0],
                                           'joint3.position': [1.5708] * 2})
    status, _, err = run(capsys, tmp_path, src, '--reference', ref)
    assert status == 1
    assert (f"--reference {ref}: its times (10.0 .. 11.0 s) do not overlap the simulation's "
            '(0.0 .. 0.002 s)') in error_line(err)


def test_too_many_steps_print_plain_numbers(tmp_path, capsys):
    src = write_csv(tmp_path / 'efforts.csv', {'time': [0.0, 1e6], 'joint3.effort': [0.0] * 2})
    status, _, err = run(capsys, tmp_path, src, '--time-step', '1e-3')
    assert status == 2
    assert re.search(r'--time-step 0\.001: 1,000,000,000 steps from t = 0\.0 to 1000000\.0 s, '
                     r'more than 100,000,000', error_line(err)), err


def test_a_step_too_small_for_the_times_prints_plain_numbers(tmp_path, capsys):
    src = write_csv(tmp_path / 'efforts.csv', {'time': [1e12, 1e12 + 1.0],
                                               'joint3.effort': [0.0] * 2})
    status, _, err = run(capsys, tmp_path, src, '--time-step', '1e-3')
    assert status == 2
    assert '--time-step 0.001: too small for times of 1000000000001.0 s' in error_line(err)


def test_the_docs_and_the_help_say_the_same_of_columns(capsys):
    """docs/cli.md's cog_id_simulate section and --help: unknown joints' columns exit 1,
    other columns are notes."""
    text = (ROOT / 'docs' / 'cli.md').read_text(encoding='utf-8')
    section = text[text.index('# Offline simulation: `cog_id_simulate`'):]
    row = next(line for line in section.splitlines() if line.startswith('| 1 |'))
    assert 'unknown column' not in row
    assert 'a column of a joint the mechanism does not have' in row
    assert 'other columns are ignored with a note' in row
    with pytest.raises(SystemExit):
        simulate.main(['--help'])
    help_text = ' '.join(capsys.readouterr().out.split())
    assert 'whose <name> is not a joint of the mechanism is an error' in help_text
    assert 'are ignored with a note, as cog_id_torques does' in help_text
