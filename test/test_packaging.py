"""The installed package: a wheel built from this checkout, installed into a fresh prefix,
loads every config it installs from where it installs it (the issue "Reliability 2", item 15).

Offline: pip of the test's interpreter builds the wheel without build isolation (setuptools
and wheel are in the venv, requirements.txt) from a copy of the checkout (so no build/ or *.egg-info lands in it), and
installs it with ``--target`` into a temporary directory: the packages go to its top, the
data files to ``<target>/share/cog_id_ros`` (the prefix's share/ of any other install).
"""
import glob
import json
import os
import shutil
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PIP = [sys.executable, '-m', 'pip', '--disable-pip-version-check', '--no-input', '--quiet']

#: run in the install, with nothing of the checkout on the path: load every
#: installed config and report the mechanism's name per file, and where cog_id_ros came from
LOAD_ALL = """
import glob, json, os, sys
import cog_id_ros
from cog_id_ros import Mechanism
loaded, failed = {}, {}
for path in sorted(glob.glob(os.path.join(sys.argv[1], '*.yaml'))):
    try:
        loaded[os.path.basename(path)] = Mechanism.from_params_file(path).name
    except Exception as exc:
        failed[os.path.basename(path)] = f'{type(exc).__name__}: {exc}'
print(json.dumps({'package': cog_id_ros.__file__, 'loaded': loaded, 'failed': failed}))
"""


def installed_env(target):
    """The environment of a program run from the install: the checkout off the path (no
    PYTHON* variable of the test run) and no ament index to fall back on."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith('PYTHON') and k != 'AMENT_PREFIX_PATH'}
    env['PYTHONPATH'] = str(target)
    return env


@pytest.fixture(scope='module')
def installed(tmp_path_factory):
    """The directory the wheel of this checkout is installed into: the packages at its
    top, the data files under its share/."""
    tmp = tmp_path_factory.mktemp('packaging')
    source = tmp / 'source'
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'out', 'build', '*.egg-info', '__pycache__', '.pytest_cache', 'test',
        'bench'))
    wheels = tmp / 'wheels'
    subprocess.run(PIP + ['wheel', '--no-deps', '--no-build-isolation', '--no-index', '-w',
                          str(wheels), str(source)], check=True, capture_output=True,
                   timeout=300)
    (wheel,) = glob.glob(str(wheels / 'cog_id_ros-*.whl'))
    # --target, not --prefix: pip installing with --prefix first uninstalls the package
    # from the running environment (here the venv's editable install of this checkout)
    target = tmp / 'target'
    subprocess.run(PIP + ['install', '--no-deps', '--no-index', '--target', str(target), wheel],
                   check=True, capture_output=True, timeout=300)
    return target


def test_every_installed_config_loads_from_the_installed_location(installed):
    """Reliability 2, item 15: setup.py installed only config/*.yaml and *.csv, so the
    installed crank_rocker_urdf.yaml could not find its crank_rocker.urdf. Every config of
    the checkout is installed, and each one loads from share/cog_id_ros/config with the
    installed package."""
    config = installed / 'share' / 'cog_id_ros' / 'config'
    env = installed_env(installed)
    result = subprocess.run([sys.executable, '-c', LOAD_ALL, str(config)], cwd=installed, env=env,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.splitlines()[-1])
    # the installed package, not the checkout's (an editable install would answer too)
    assert report['package'].startswith(str(installed)), report['package']
    assert report['failed'] == {}
    shipped = sorted(os.path.basename(p) for p in glob.glob(os.path.join(REPO, 'config', '*')))
    assert sorted(os.listdir(config)) == shipped
    yamls = [name for name in shipped if name.endswith('.yaml')]
    assert sorted(report['loaded']) == yamls
    assert 'crank_rocker_urdf.yaml' in report['loaded']


#: run in the install: where the package and the demos' config directory are
WHERE = """
import cog_id_ros
from cog_id_ros.demos.paper_four_bar import config_dir
print(cog_id_ros.__file__)
print(config_dir())
"""


def test_the_installed_demo_table_runs_from_another_directory(installed, tmp_path):
    """Reliability 2, adversarial check: after installing the wheel, cog_id_demo and
    ``python -m cog_id_ros.demos.table`` run from another directory died with a traceback
    "cannot read <site-packages>/config/paper_four_bar_a.yaml": config_dir knew only a
    source checkout's config/ and the ament index. It now also looks in the installed
    share/cog_id_ros/config (here the one beside the package, pip --target), and the
    installed demo prints the table."""
    env = installed_env(installed)
    script = installed / 'bin' / 'cog_id_demo'
    assert script.is_file()
    for command in ([sys.executable, '-m', 'cog_id_ros.demos.table'], [str(script)]):
        result = subprocess.run(command + ['--step', '0.5'], cwd=tmp_path, env=env,
                                capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stderr
        assert result.stderr == ''
        lines = result.stdout.splitlines()
        assert lines[0].startswith('paper four-bar (Sonoda, Ishii, Isobe)'), result.stdout
        assert len(lines) == 2 + 5 + 1                  # title, header, t = 0 to 2 s, peak
        assert lines[-1].startswith('peak |tau|: (a) 6.7593 Nm; (b) 3.3797 / 3.3797 Nm')
    # the installed package with the installed config files, not the checkout's
    result = subprocess.run([sys.executable, '-c', WHERE], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    package, config = result.stdout.splitlines()[-2:]
    assert package.startswith(str(installed)), package
    assert config == str(installed / 'share' / 'cog_id_ros' / 'config')
