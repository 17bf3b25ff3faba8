"""``cog_id_node --help`` lists the node's modes.

Issue: "``cog_id_node --help`` names neither ``control_mode`` nor ``managed``": a user
asking the program how to run it learnt of neither the feedback modes nor the lifecycle
node. The help lists both, with their values and defaults, from the node's parameter table.
"""
import os
import subprocess
import sys

from cog_id_ros.ros.command_line import MODE_PARAMETERS, modes_help
from cog_id_ros.ros.parameters import CONTROL_MODES, NODE_PARAMETERS

BIN = os.path.dirname(sys.executable)


def test_the_modes_come_from_the_parameter_table():
    text = modes_help()
    assert 'control_mode:=' + '|'.join(CONTROL_MODES) in text
    assert 'managed:=true' in text
    for name in MODE_PARAMETERS:
        what = NODE_PARAMETERS[name].ros_description.split(': ', 1)[0]
        assert what in text, (name, what)
    assert 'default feedforward' in text and 'default false' in text


def test_cog_id_node_help_names_its_modes():
    """The console script, as a user runs it: exit status 0 at once (no ROS discovery:
    nothing of rclpy is started), the usage and the modes on stdout."""
    script = os.path.join(BIN, 'cog_id_node')
    command = [script] if os.path.exists(script) else [sys.executable, '-m', 'cog_id_ros.node']
    for flag in ('--help', '-h'):
        result = subprocess.run(command + [flag], capture_output=True, text=True, timeout=60)
        assert result.returncode == 0, result.stderr
        assert result.stdout.startswith('usage: cog_id_node'), result.stdout
        assert 'control_mode' in result.stdout and 'managed' in result.stdout, result.stdout
        assert 'computed_torque' in result.stdout and 'managed:=true' in result.stdout
        assert result.stderr == ''


def test_the_readme_runs_the_console_scripts_from_the_virtual_environment():
    """Issue: the README ran ``cog_id_node`` (and cog_sim_node, cog_id_player,
    cog_id_inspect) as bare commands, which ``./dev setup`` installs into .venv/bin, not on
    the PATH: a newcomer's copy said "command not found". Every command a shell snippet (or
    an inline command) of the README starts is ``.venv/bin/<script>``."""
    import pathlib
    import re
    repo = pathlib.Path(__file__).resolve().parents[2]
    scripts = re.findall(r"'(\w+) = cog_id_ros\.", (repo / 'setup.py').read_text())
    assert 'cog_id_node' in scripts and 'cog_id_inspect' in scripts
    readme = (repo / 'README.md').read_text(encoding='utf-8')
    snippets = re.findall(r'```(?:bash|sh)\n(.*?)```', readme, re.S)
    commands = [part.strip() for snippet in snippets for line in snippet.splitlines()
                for part in re.split(r'[&|;]', line)]
    commands += re.findall(r'`([\w./]+ --[^`]*)`', readme)        # inline: `tool --option`
    bare = [command for command in commands if command.split(' ', 1)[0] in scripts]
    assert bare == []
    assert any(command.startswith('.venv/bin/cog_id_node ') for command in commands)
