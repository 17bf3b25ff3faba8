"""The linter and the type checker are part of the test command: ruff (ruff.toml: ROS 2's
flake8 conventions) on cog_id_ros/, test/ and bench/, and mypy (setup.cfg [mypy]: every
function of cog_id_ros/core/ and cog_id_ros/ros/ annotated, and the annotations hold), must
find nothing."""
import importlib.util
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


def test_mypy_finds_nothing():
    if importlib.util.find_spec('mypy') is None:
        pytest.fail('mypy is not installed (requirements.txt pins it; ./dev setup installs it)')
    # no cache: a run reads the sources as they are, and leaves nothing in the repository
    result = subprocess.run([sys.executable, '-m', 'mypy', '--config-file', 'setup.cfg',
                             '--cache-dir', os.devnull],
                            cwd=REPO, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, 'mypy (setup.cfg [mypy]):\n' + result.stdout + result.stderr
