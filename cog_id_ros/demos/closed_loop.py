"""The closed-loop demo: cog_id_node in each control mode on the paper four-bar, closed
through cog_sim_node over real ROS 2 topics, and a picture of the tracking error.

    ./dev control            (python -m cog_id_ros.demos.closed_loop [--output PNG] [--seconds S])

What it does: for each mode (``feedforward``, ``computed_torque`` with kp 400 and kd 40,
``pd_feedforward`` with the same rates at the start pose, ``gravity_compensation``) it
starts, in a namespace of its own, one ``cog_sim_node`` (the plant: the paper four-bar
started 0.1 rad off the target, ``wait_for_effort:=true`` so it holds that pose until the
first command, ``lockstep:=true`` so it steps once per command, ``joint_states`` after
every step, whatever the load of the machine) and one ``cog_id_node`` on
config/paper_four_bar_a.yaml
(``-r measured_joint_states:=joint_states``, ``joint_states_decimation:=0``; its
``effort_command`` is the simulator's input without a remap). The target is the paper's
motion theta(t) = pi/2 + 0.5 sin(pi t), played on simulated time by a player in this
process (demos/sim_player.py): once every path carried data (probes of the plant's pose
at rest until the node counts one, its joint_effort heard, the simulator stepping) the
run starts at the next simulated state t0, and for each simulated state at t the player
publishes the setpoint of t - t0 + one step, so the setpoint in force when the node
answers the next state is that state's. Gravity compensation gets no setpoint and holds
its start pose. It writes the tracking error of each mode over time to ``--output``
(out/closed_loop.png) and each node's log beside it (closed_loop_logs/), prints a table
and exits 0 when computed torque is below 1e-3 rad from 0.5 s on and gravity
compensation held its pose to 1e-4 rad; 1 when not, or when data were lost (a simulated
step missing from ``joint_states``, a state or setpoint left without its command, a
setpoint the node's /diagnostics do not count as accepted: each is said); 2 when it did
not run (no config file, a node that did not start, paths that did not connect).

It uses ROS_DOMAIN_ID from the environment (or one picked from the process id, printed),
with discovery limited to this machine.
"""
import argparse
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Sequence

import numpy as np

from .paper_four_bar import ConfigNotFound, config_dir, target_motion

#: the modes shown, with the node's extra parameters
MODES = {
    'feedforward': (),
    'computed_torque': ('-p', 'kp:=[400.0]', '-p', 'kd:=[40.0]'),
    'pd_feedforward': ('-p', 'pd_kp:=[{kp}]', '-p', 'pd_kd:=[{kd}]'),
    'gravity_compensation': (),
}
START_ERROR = 0.1     # rad
H = 0.001             # s: the simulator's step
#: simulated seconds per wall second at most. The simulator in lockstep waits for each
#: command, so a late command never acts a step late; the player (this process, Python)
#: publishes the target on each simulated state, and at 1 kHz a loaded machine leaves it
#: behind (a run at 1.0 drew PD plus feed-forward 0.3 rad off its target for half a
#: second): at 0.2 a step is 5 ms of wall time, time enough for it too
REAL_TIME_FACTOR = 0.2
#: s of wall time the commands of the last states may take to arrive
SETTLE = 5.0
#: lines of the nodes' logs looked at for warnings when data were lost
LOG_LINES = 20


def target(t: float) -> tuple[list[float], list[float]]:
    """The paper's target motion (positions, velocities: paper_four_bar.target_motion)."""
    theta, rate, _ = target_motion(t)
    return [float(theta)], [float(rate)]


def plant_params(config: str, directory: str) -> str:
    """The parameter file with the parallelogram started START_ERROR off the target."""
    import yaml

    from ..description import yaml_guard
    with open(config, encoding='utf-8') as stream:
        doc = yaml_guard.load(stream.read(), yaml.SafeLoader, 'params_file', config)
    theta = target(0.0)[0][0] + START_ERROR
    doc['/**']['ros__parameters']['mechanism']['initial_positions'] = [
        theta, -theta, theta, theta]
    path = os.path.join(directory, 'plant.yaml')
    with open(path, 'w', encoding='utf-8') as stream:
        yaml.safe_dump(doc, stream)
    return path


def launch(command: Sequence[str]) -> Any:
    return subprocess.Popen([sys.executable, '-m', *command], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def start_sim(plant: str, namespace: str) -> Any:
    """cog_sim_node, the plant, holding its start pose until the first command."""
    return launch(['cog_id_ros.ros.sim_main', '--ros-args', '--params-file', plant,
                  '-r', f'__ns:={namespace}', '-p', 'wait_for_effort:=true',
                  '-p', 'lockstep:=true', '-p', f'real_time_factor:={REAL_TIME_FACTOR}',
                  '-p', f'time_step:={H}',
                  '-p', 'joint_states_period:=0.0', '-p', 'effort_timeout:=0.0'])


def start_node(config: str, namespace: str, mode: str, extra: Sequence[str]) -> Any:
    """cog_id_node in ``mode``, its measured states the simulator's joint_states."""
    return launch(['cog_id_ros.node', '--ros-args', '--params-file', config,
                  '-r', f'__ns:={namespace}', '-r', 'measured_joint_states:=joint_states',
                  '-p', f'control_mode:={mode}', '-p', 'joint_states_decimation:=0',
                  '-p', 'measurement_timeout:=2.0', '-p', 'setpoint_timeout:=2.0',
                  '-p', 'diagnostics_period:=0.1', *extra])


def wait_started(proc: Any, timeout: float = 60.0) -> str:
    """The node's output up to its start-up line ('' if it ended or did not start); from
    then on a thread reads the rest into ``proc.log`` (a node blocked on a full pipe would
    lose data)."""
    lines: list[str] = []
    proc.log = lines
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            return ''
        lines.append(line)
        if "mechanism '" in line:
            threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True).start()
            return ''.join(lines)
    return ''


def stop(proc: Any) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(15)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def save_logs(procs: Sequence[Any], mode: str, log_dir: str) -> None:
    """Each node's output, whole, in ``log_dir``/<mode>_<node>.log."""
    os.makedirs(log_dir, exist_ok=True)
    for name, proc in zip(('cog_sim_node', 'cog_id_node'), procs):
        with open(os.path.join(log_dir, f'{mode}_{name}.log'), 'w', encoding='utf-8') as out:
            out.writelines(getattr(proc, 'log', []))


def run_mode(context: Any, config: str, plant: str, mode: str, seconds: float,
             log_dir: str) -> dict[str, Any]:
    """One mode: the simulator, the player hearing it, then the node; the run's results."""
    import cog_id_ros

    from .sim_player import SimPlayer
    mech = cog_id_ros.Mechanism.from_params_file(config)
    inertia = float(cog_id_ros.InverseDynamics(mech).equation_of_motion([math.pi / 2])[0][0, 0])
    extra = [a.format(kp=400 * inertia, kd=40 * inertia) for a in MODES[mode]]
    namespace = f'/closed_loop_{mode}'
    tracks = mode != 'gravity_compensation'
    procs = [start_sim(plant, namespace)]
    player = None
    try:
        if not wait_started(procs[0]):
            raise RuntimeError(f'cog_sim_node ({mode}) did not start')
        player = SimPlayer(context, namespace, mech, H, target if tracks else None,
                           feedback=mode != 'feedforward')
        if not player.heard():
            raise RuntimeError(f'no joint_states from cog_sim_node ({mode})')
        procs.append(start_node(config, namespace, mode, extra))
        if not wait_started(procs[1]):
            raise RuntimeError(f'cog_id_node ({mode}) did not start')
        missing = player.connect()
        if missing:
            raise RuntimeError(f'cog_id_node and cog_sim_node ({mode}) did not connect: '
                               f'{missing}')
        if not player.wait(seconds, timeout=seconds / REAL_TIME_FACTOR * 4 + 30):
            raise RuntimeError(f'cog_sim_node ({mode}) did not reach {seconds:g} s of '
                               'simulated time')
        out = player.results(seconds, settle=SETTLE)
        if out['lost']:
            out['lost'] += [f'{name}: {line.rstrip()}' for name, proc in
                            zip(('cog_sim_node', 'cog_id_node'), procs)
                            for line in proc.log[-LOG_LINES:] if 'WARN' in line
                            or 'ERROR' in line]
    finally:
        if player is not None:
            player.close()
        for proc in reversed(procs):
            stop(proc)
        save_logs(procs, mode, log_dir)
    if not tracks:
        out['setpoints'] = np.full_like(out['positions'], out['positions'][0])
    return out


def plot(results: dict[str, dict[str, np.ndarray]], output: str) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4.5))
    labels = {'feedforward': 'feed-forward alone',
              'computed_torque': 'computed torque (kp 400, kd 40)',
              'pd_feedforward': 'PD + feed-forward (same rates at the start pose)',
              'gravity_compensation': 'gravity compensation (no setpoint: holds its pose)'}
    for mode, out in results.items():
        error = np.abs(out['setpoints'] - out['positions'])[:, 0]
        ax.semilogy(out['time'], np.maximum(error, 1e-12), label=labels[mode])
    ax.axhline(1e-3, color='grey', lw=0.8, ls='--')
    ax.set_xlabel('time (s)')
    ax.set_ylabel('|tracking error| (rad)')
    ax.set_title('cog_id_node closed through cog_sim_node (paper four-bar), start 0.1 rad off')
    ax.legend(fontsize=8, loc='lower left')
    ax.grid(True, which='both', alpha=0.3)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(output)), exist_ok=True)
    fig.savefig(output, dpi=110)


def summary(results: dict[str, dict[str, np.ndarray]]) -> bool:
    """Print the table; whether computed torque and gravity compensation did their part."""
    print(f"{'mode':<22} {'error at 0 s':>13} {'median after 0.5 s':>19} "
          f"{'max after 0.5 s':>16}")
    ok = True
    for mode, out in results.items():
        error = np.abs(out['setpoints'] - out['positions'])[:, 0]
        late = error[out['time'] >= 0.5]
        print(f'{mode:<22} {error[0]:13.3g} {np.median(late):19.3g} {late.max():16.3g}')
        if mode == 'computed_torque':
            ok &= bool(late.max() < 1e-3)
        if mode == 'gravity_compensation':
            ok &= bool(error.max() < 1e-4)
    for mode, out in results.items():
        for line in out['lost']:
            print(f'{mode}: lost data: {line}')
            ok = False
    return ok


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m cog_id_ros.demos.closed_loop',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('--output', default='out/closed_loop.png')
    parser.add_argument('--seconds', type=float, default=2.0)
    args = parser.parse_args(argv)
    try:
        config = os.path.join(config_dir(), 'paper_four_bar_a.yaml')
    except ConfigNotFound as exc:
        print(f'closed_loop: {exc}', file=sys.stderr)
        return 2
    if 'ROS_DOMAIN_ID' not in os.environ:
        os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 101)
        print(f"closed_loop: ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}")
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    try:
        with tempfile.TemporaryDirectory(prefix='closed_loop_') as directory:
            plant = plant_params(config, directory)
            log_dir = os.path.join(os.path.dirname(os.path.abspath(args.output)),
                                   'closed_loop_logs')
            results = {mode: run_mode(context, config, plant, mode, args.seconds, log_dir)
                       for mode in MODES}
    except RuntimeError as exc:
        print(f'closed_loop: {exc}', file=sys.stderr)
        return 2
    finally:
        context.try_shutdown()
    plot(results, args.output)
    ok = summary(results)
    print(f'picture: {args.output}')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
