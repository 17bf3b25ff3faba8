"""Every YAML the package reads goes through one nesting guard (cog_id_ros.description.yaml_guard).

Issue (high): a loop-closure file of one line of 25,000 nested ``- `` entries (50 kB, under
its size cap) crashed cog_id_inspect, cog_id_node, cog_sim_node and a managed node at
configure (SIGSEGV, exit 139): PyYAML's C loader builds nested nodes recursively, and the
loop-closure reader checked only the depth of ``[`` and ``{``. Issue (low): a parameter
file of 700 nested mappings and an array rcl refuses ended cog_id_node with a
RecursionError traceback (exit 1): after rcl refused the array, the node re-read the file
with PyYAML's recursive pure-Python composer to name the parameter at rcl's line.

Each file is loaded in a child process, so that a crash shows as a negative return code
instead of killing the test run.
"""
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys

import pytest

import cog_id_ros
from cog_id_ros.description import yaml_guard

REPO = pathlib.Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config'
ENV = {**os.environ, 'PYTHONPATH': str(REPO)}

#: loads a params file in a child process; prints the exception's type, parameter, message
LOAD_CHILD = r"""
import json, sys
import cog_id_ros
try:
    cog_id_ros.Mechanism.from_params_file(sys.argv[1])
    out = {'type': None}
except Exception as exc:
    out = {'type': type(exc).__name__, 'parameter': getattr(exc, 'parameter', None),
           'message': str(exc)}
print(json.dumps(out))
"""

DEEP = 25_000

#: texts that nest far beyond the guard's depth, each small
DEEP_TEXTS = {
    'a line of block entries': '- ' * DEEP + 'x\n',
    'a line of explicit keys': '? ' * DEEP + 'x\n',
    'indented mappings': ''.join(' ' * k + f'k{k}:\n' for k in range(600)),
    'block entries then flow': '- ' * 20 + '[' * 20 + ']' * 20 + '\n',
    'flow single-pair mappings': '[a: ' * 30 + 'x' + ']' * 30 + '\n',
    'flow sequences': '[' * DEEP + ']' * DEEP + '\n',
    'indented mappings, CR line breaks': '\r'.join(' ' * k + f'k{k}:' for k in range(600)),
}


def _run(args, cwd=None, timeout=120):
    try:
        return subprocess.run(args, capture_output=True, text=True, timeout=timeout, cwd=cwd,
                              env=ENV)
    except subprocess.TimeoutExpired:
        pytest.fail(f'{args[:4]} did not finish within {timeout} s')


def _talos_with_loop_file(tmp_path, loop_text):
    """The TALOS-like leg's params file and URDF in ``tmp_path``, its loop-closure file
    holding ``loop_text``."""
    shutil.copy(CONFIG / 'talos_like_leg.urdf', tmp_path)
    shutil.copy(CONFIG / 'talos_like_leg.yaml', tmp_path)
    (tmp_path / 'talos_like_leg_loops.yml').write_text(loop_text, encoding='utf-8')
    return tmp_path / 'talos_like_leg.yaml'


def _load_in_child(path):
    done = _run([sys.executable, '-c', LOAD_CHILD, str(path)])
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_loop_file_of_deeply_nested_block_entries_is_a_config_error(tmp_path):
    """Issue (high): 25,000 nested '- ' on one line of the loop-closure file crashed the
    process (exit -11 here); now MechanismConfigError on mechanism.loop_closure_file."""
    params = _talos_with_loop_file(tmp_path, '- ' * DEEP + 'x\n')
    out = _load_in_child(params)
    assert out['type'] == 'MechanismConfigError', out
    assert out['parameter'] == 'mechanism.loop_closure_file', out
    assert 'talos_like_leg_loops.yml' in out['message'] and '32 deep' in out['message'], out
    assert '\n' not in out['message']


def test_cog_id_inspect_on_a_deeply_nested_loop_file_exits_2_with_one_line(tmp_path):
    """Issue (high): cog_id_inspect crashed (exit 139) on the same files."""
    params = _talos_with_loop_file(tmp_path, '- ' * DEEP + 'x\n')
    done = _run([sys.executable, '-m', 'cog_id_ros.offline.inspect', '--params-file',
                 str(params)], cwd=tmp_path)
    assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert 'mechanism.loop_closure_file' in lines[0] and 'talos_like_leg_loops.yml' in lines[0]
    assert 'Traceback' not in done.stderr


@pytest.mark.parametrize('case', sorted(DEEP_TEXTS))
def test_every_deep_loop_file_is_a_config_error(case, tmp_path):
    """Block sequences, explicit keys, indented mappings, flow collections and mixes."""
    out = _load_in_child(_talos_with_loop_file(tmp_path, DEEP_TEXTS[case]))
    assert (out['type'], out['parameter']) == ('MechanismConfigError',
                                               'mechanism.loop_closure_file'), out


@pytest.mark.parametrize('case', sorted(DEEP_TEXTS))
def test_every_deep_params_file_is_a_config_error(case, tmp_path):
    path = tmp_path / 'deep.yaml'
    path.write_text(DEEP_TEXTS[case], encoding='utf-8')
    out = _load_in_child(path)
    assert (out['type'], out['parameter']) == ('MechanismConfigError', 'params_file'), out
    assert re.search(r'\(line \d+\)', out['message']), out


def _deep_mappings_and_a_mixed_array(tmp_path, depth=700):
    """Issue (low): 700 nested mappings under ros__parameters, and an array rcl refuses."""
    lines = ['/**:', '  ros__parameters:', '    gravity: [0, -9.81, 0]']
    lines += [' ' * (4 + k) + f'k{k}:' for k in range(depth)]
    lines.append(' ' * (4 + depth) + 'x: 1.0')
    path = tmp_path / 'deep_mappings.yaml'
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def test_cog_id_node_on_deep_mappings_and_a_mixed_array_exits_2_with_one_line(tmp_path):
    """Issue (low): the node said RecursionError in a traceback, exit status 1 (rcl refused
    the array; the node's second reading of the file, to name the parameter, recursed).
    The node stops at its own check of the file, before rclpy is initialised."""
    path = _deep_mappings_and_a_mixed_array(tmp_path)
    done = _run([sys.executable, '-m', 'cog_id_ros.node', '--ros-args', '--params-file',
                 str(path)], cwd=tmp_path)
    assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and 'deep_mappings.yaml' in lines[0], done.stderr
    assert 'Traceback' not in done.stderr and 'RecursionError' not in done.stderr


def test_cog_id_inspect_and_the_api_on_deep_mappings_and_a_mixed_array(tmp_path):
    path = _deep_mappings_and_a_mixed_array(tmp_path)
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_params_file(str(path))
    assert info.value.parameter == 'params_file'
    done = _run([sys.executable, '-m', 'cog_id_ros.offline.inspect', '--params-file',
                 str(path)], cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_the_node_names_the_parameter_at_rcls_line_without_recursing(tmp_path):
    """The node's second reading of a file rcl refused (to name the parameter at rcl's
    line) goes through the guard: a file too deep to build is no name, not RecursionError."""
    from cog_id_ros.ros.command_line import _parameter_at_line
    deep = _deep_mappings_and_a_mixed_array(tmp_path)
    assert _parameter_at_line(str(deep), 40) is None
    shallow = _deep_mappings_and_a_mixed_array(tmp_path, depth=3)
    assert _parameter_at_line(str(shallow), 3) == 'gravity'


def test_a_deep_command_line_value_is_not_a_recursion_error():
    """``-p managed:=[[[...]]]`` (the node reads ``managed`` before rclpy does) was read by
    PyYAML's recursive pure-Python loader: RecursionError. Now the value is not taken (rcl
    says what is wrong with it)."""
    from cog_id_ros.ros.command_line import given_value
    argv = ['--ros-args', '-p', 'managed:=' + '[' * 5000 + ']' * 5000]
    assert given_value(argv, 'cog_id_node', 'managed', False) is False
    assert given_value(['--ros-args', '-p', 'managed:=true'], 'cog_id_node', 'managed') is True


def test_nesting_within_the_depth_loads():
    """MAX_DEPTH collections, block and flow mixed, load; one more is refused."""
    def text(depth):
        block = depth // 2
        return ''.join(' ' * k + 'k:\n' for k in range(block)) + ' ' * block + \
            '[' * (depth - block) + ']' * (depth - block) + '\n'
    depth = yaml_guard.MAX_DEPTH
    value = yaml_guard.load(text(depth), yaml_guard._Loader, 'p', 'f')
    levels = 1                      # the innermost list, empty
    while value:
        value = value['k'] if isinstance(value, dict) else value[0]
        levels += 1
    assert levels == depth
    with pytest.raises(cog_id_ros.MechanismConfigError, match=r'^p: f nests .* \(line'):
        yaml_guard.load(text(depth + 1), yaml_guard._Loader, 'p', 'f')


def test_the_example_files_load_through_the_guard():
    for path in sorted(CONFIG.glob('*.y*ml')):
        yaml_guard.check_nesting(path.read_text(encoding='utf-8'), 'params_file', path)


def test_no_yaml_is_built_outside_the_guard():
    """One guard: no module of the package builds a YAML document but yaml_guard."""
    builders = re.compile(r'\byaml\.(?:safe_|full_|unsafe_)?(?:load|compose)(?:_all)?\(')
    found = [f'{path.relative_to(REPO)}:{number}'
             for path in sorted((REPO / 'cog_id_ros').rglob('*.py'))
             if path.name != 'yaml_guard.py'
             for number, line in enumerate(path.read_text(encoding='utf-8').splitlines(), 1)
             if builders.search(line)]
    assert found == []
