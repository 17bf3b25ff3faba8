"""Shared fixtures: every test session talks DDS on a ROS_DOMAIN_ID of its own.

The domain is chosen from the run's pid (1..100; under pytest-xdist the workers' parent's,
plus the worker's index, so the two workers of a run never share one) and set in the
environment when this file is imported, i.e. before any test module can call
``rclpy.init``; subprocesses inherit it (``ros_env`` gives a copy for ``subprocess``). Discovery stays on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), so parallel test runs never cross-talk.
Set ``COG_ID_TEST_DOMAIN_ID`` to force a domain (each worker adds its index to it).

Fixtures:
  ros_env        environment for ROS subprocesses (the session's domain)
  rclpy_context  an initialised rclpy Context for the session (shut down at the end)
  ros_process    factory: start a ROS program as a subprocess; stopped with SIGINT at the end
                 of the test module (so a module starts its nodes once)

and ``wait_until(predicate, timeout)`` for tests that wait on DDS traffic.
"""
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

_WORKER = os.environ.get('PYTEST_XDIST_WORKER', '')      # 'gw0', 'gw1': pytest-xdist's
_INDEX = int(_WORKER[2:]) if _WORKER.startswith('gw') else 0
_BASE = os.getppid() if _WORKER else os.getpid()           # the run's, shared by its workers
DOMAIN_ID = int(os.environ.get('COG_ID_TEST_DOMAIN_ID', 1 + (_BASE % 20) * 5)) + _INDEX % 5
os.environ['ROS_DOMAIN_ID'] = str(DOMAIN_ID)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_STATIC_PEERS', None)

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.dirname(sys.executable)


def wait_until(predicate, timeout=20.0):
    """True once ``predicate()`` is true; polls every 10 ms for at most ``timeout`` s (an
    upper bound, never reached when things work)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@pytest.fixture(scope='session')
def ros_env():
    """A copy of the environment for ROS subprocesses: the session's domain, unbuffered."""
    env = dict(os.environ)
    env['PYTHONUNBUFFERED'] = '1'
    env['RCUTILS_COLORIZED_OUTPUT'] = '0'
    return env


@pytest.fixture(scope='session')
def rclpy_context():
    """An rclpy Context of the session, initialised once (no signal handlers of its own)."""
    rclpy = pytest.importorskip('rclpy')
    from rclpy.signals import SignalHandlerOptions
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    yield context
    context.try_shutdown()


class RosProcess:
    """A ROS program running as a subprocess; its output is collected in ``output``."""

    def __init__(self, args, env, cwd=REPO):
        self.args = list(args)
        self.proc = subprocess.Popen(self.args, env=env, cwd=cwd, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self._lines = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self._lines.append(line)

    @property
    def output(self):
        return ''.join(self._lines)

    def wait_for_output(self, text, timeout=30.0):
        """True once ``text`` appeared in the output (False if the process ended first)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if text in self.output:
                return True
            if self.proc.poll() is not None:
                self._reader.join(timeout=2)
                return text in self.output
            time.sleep(0.05)
        return False

    def stop(self, sig=signal.SIGINT, timeout=15.0):
        """Send ``sig`` and wait; returns the exit status (killed after ``timeout``)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(timeout=2)
        if not self._reader.is_alive():
            self.proc.stdout.close()    # read to its end: closed, not left to the collector
        return self.proc.returncode


@pytest.fixture(scope='module')
def ros_process(ros_env):
    """Factory ``ros_process(args, env=None)`` -> RosProcess; every one is stopped at teardown.

    ``args[0]`` may name a console script of the venv (``cog_id_node``).
    """
    started = []

    def start(args, env=None):
        args = list(args)
        exe = os.path.join(BIN, args[0])
        if os.path.exists(exe):
            args[0] = exe
        started.append(RosProcess(args, env or ros_env))
        return started[-1]

    yield start
    for proc in started:
        proc.stop()
