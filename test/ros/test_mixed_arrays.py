"""Arrays rcl's parameter-file parser refuses are refused alike by cog_id_node and the API.

rcl refuses ``gravity: [0, -9.81, 0]`` (integers and doubles in one array); the node reads
its files first and names the parameter. ``cog_id_ros.description.params_file`` holds the one rule
(``rcl_value_problem``), so ``Mechanism.from_params_file`` refuses the same files with
the same message, while a dict given to ``Mechanism.from_parameters`` may mix freely.
"""
import pathlib
import signal
import subprocess
import sys

from conftest import REPO
import numpy as np
import pytest

import cog_id_ros
from cog_id_ros import MechanismConfigError
from cog_id_ros.description import params_file

CONFIG_A = 'config/paper_four_bar_a.yaml'
MIXED = 'the array mixes integers and doubles ([0, -9.81, 0])'


def mixed_file(tmp_path, old='gravity: [0.0, -9.81, 0.0]', new='gravity: [0, -9.81, 0]',
               name='mixed.yaml'):
    text = pathlib.Path(f'{REPO}/{CONFIG_A}').read_text(encoding='utf-8')
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new))
    return str(path)


def api_error(path):
    with pytest.raises(MechanismConfigError) as error:
        cog_id_ros.Mechanism.from_params_file(path)
    return error.value


def test_the_api_refuses_a_file_that_mixes_integers_and_doubles(tmp_path):
    path = mixed_file(tmp_path)
    error = api_error(path)
    assert error.parameter == 'mechanism.gravity'
    assert str(error) == (f"mechanism.gravity: {MIXED}, which ROS 2's parameter file parser "
                          f'refuses: write every number as a double (0.0, not 0) (in {path})')
    with pytest.raises(MechanismConfigError, match='mixes integers and doubles'):
        params_file.load_params_file(path)


def test_a_dict_may_mix_integers_and_floats():
    params = params_file.load_params_file(f'{REPO}/{CONFIG_A}')
    assert params['mechanism.gravity'] == [0.0, -9.81, 0.0]
    mixed = cog_id_ros.Mechanism.from_parameters(dict(params, **{'mechanism.gravity':
                                                                 [0, -9.81, 0]}))
    assert list(mixed.gravity) == [0.0, -9.81, 0.0]
    solver = cog_id_ros.InverseDynamics(mixed)
    reference = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params))
    np.testing.assert_array_equal(solver.torques([1.4], [0.3], [0.1]),
                                  reference.torques([1.4], [0.3], [0.1]))


@pytest.mark.parametrize('value, problem', [
    ([0, -9.81, 0], 'mixes integers and doubles'),
    (['joint1', 2], 'mixes types'),
    ([True, 1.0], 'mixes types'),
    ([0, 0, 1], None),
    ([0.0, 1e9], None),
    (['a', 'b'], None),
    ([], None),
    (1, None),
])
def test_the_rule(value, problem):
    found = params_file.rcl_value_problem(value)
    assert (found is None) if problem is None else (problem in found)


def test_floats_without_a_dot_are_doubles_as_rcl_reads_them(tmp_path):
    """[0.0, -9.81, 1e-12] is an array of doubles for rcl (PyYAML's own loader reads 1e-12
    as a string, which once made the node refuse it as 'mixes types')."""
    path = mixed_file(tmp_path, new='gravity: [0.0, -9.81, 1e-12]')
    assert cog_id_ros.Mechanism.from_params_file(path).gravity[2] == 1e-12


def test_another_nodes_entry_counts_too(tmp_path):
    """rcl refuses the whole file, whichever node an entry is for."""
    path = tmp_path / 'two_nodes.yaml'
    path.write_text(pathlib.Path(f'{REPO}/{CONFIG_A}').read_text(encoding='utf-8') +
                    'other_node:\n  ros__parameters:\n    offsets: [1, 2.5]\n')
    error = api_error(str(path))
    assert error.parameter == 'offsets' and 'mixes integers and doubles' in str(error)


# --- the node: the same rule, the same message ------------------------------------------------

def run_node(ros_env, path, *extra, timeout=60):
    return subprocess.run([sys.executable, '-m', 'cog_id_ros.node', '--ros-args',
                           '--params-file', path, *extra], env=ros_env, cwd=REPO,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.parametrize('old, new', [
    ('gravity: [0.0, -9.81, 0.0]', 'gravity: [0, -9.81, 0]'),
    ('com: [0.25, 0.0, 0.0]', "com: [0.25, '0', 0.0]"),
])
def test_the_node_refuses_the_file_with_the_apis_message(tmp_path, ros_env, old, new):
    pytest.importorskip('rclpy')
    path = mixed_file(tmp_path, old, new)
    result = run_node(ros_env, path, '-r', '__ns:=/mixed', timeout=30)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert lines == [f'cog_id_node: cannot start: {api_error(path)}']


def test_the_node_starts_on_doubles_written_without_a_dot(tmp_path, ros_env):
    pytest.importorskip('rclpy')
    path = mixed_file(tmp_path, new='gravity: [0.0, -9.81, 1e-12]')
    proc = subprocess.Popen([sys.executable, '-m', 'cog_id_ros.node', '--ros-args',
                             '--params-file', path, '-r', '__ns:=/nodot'], cwd=REPO,
                            env=ros_env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        first = proc.stdout.readline()
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    assert "mechanism 'paper_four_bar_a'" in first, first + out
    assert proc.returncode == 0, out


def test_the_example_files_pass():
    for name in ('paper_four_bar_a', 'paper_four_bar_b', 'stewart_6ups', 'delta_3rus'):
        path = f'{REPO}/config/{name}.yaml'
        params_file.check_rcl_values(params_file.read_document(path), path)
