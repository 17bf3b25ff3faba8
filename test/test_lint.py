"""The linter is part of the test command: ruff (ruff.toml: ROS 2's flake8 conventions) on
cog_id_ros/, test/ and bench/ must find nothing."""
import os
import shutil
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def ruff_command():
    beside = os.path.join(os.path.dirname(sys.executable), 'ruff')
    if os.path.exists(beside):
        return [beside]
    found = shutil.which('ruff')
    if found:
        return [found]
    pytest.fail('ruff is not installed (requirements.txt pins it; ./dev setup installs it)')


def test_ruff_finds_nothing():
    result = subprocess.run([*ruff_command(), 'check', '--no-cache', '--output-format',
                             'concise', 'cog_id_ros', 'test', 'bench'],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, 'ruff check (ruff.toml):\n' + result.stdout + result.stderr
