"""The closed-loop demo: cog_id_node in each control mode on the paper four-bar, closed
through a simulated plant over real ROS 2 topics, and a picture of the tracking error.

    ./dev control            (python -m cog_id_ros.demos.closed_loop [--output PNG] [--seconds S])

What it does: for each mode (``feedforward``, ``computed_torque`` with kp 400 and kd 40,
``pd_feedforward`` with the same rates at the start pose, ``gravity_compensation``) it
starts one ``cog_id_node`` on config/paper_four_bar_a.yaml in a namespace of its own and
closes it through :class:`.lockstep_plant.LockstepPlant` (a ``cog_id_ros.Simulation`` of
the same mechanism, stepped in lockstep with the node's commands: each step's setpoint on
``joint_setpoint``, the simulated state on ``measured_joint_states``, the node's
``effort_command`` held over the step). The target is the paper's motion
theta(t) = pi/2 + 0.5 sin(pi t), from a start 0.1 rad off; gravity compensation gets no
setpoint and holds its start pose. It writes the tracking error of each mode over time to
``--output`` (out/closed_loop.png), prints a table and exits 0 when computed torque is
below 1e-3 rad from 0.5 s on and gravity compensation held its pose to 1e-4 rad; 1 when
not; 2 when it did not run (no config file, a node that did not start).

It uses ROS_DOMAIN_ID from the environment (or one picked from the process id, printed),
with discovery limited to this machine.
"""
import argparse
import math
import os
import signal
import subprocess
import sys
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
H = 0.001             # s: the plant's step


def target(t: float) -> tuple[list[float], list[float]]:
    """The paper's target motion (positions, velocities: paper_four_bar.target_motion)."""
    theta, rate, _ = target_motion(t)
    return [float(theta)], [float(rate)]


def start_node(config: str, mode: str, extra: Sequence[str]) -> tuple[Any, str]:
    namespace = f'/closed_loop_{mode}'
    proc = subprocess.Popen(
        [sys.executable, '-m', 'cog_id_ros.node', '--ros-args', '--params-file', config,
         '-r', f'__ns:={namespace}', '-p', f'control_mode:={mode}',
         '-p', 'measurement_timeout:=2.0', '-p', 'setpoint_timeout:=2.0', *extra],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return proc, namespace


def wait_started(proc: Any, timeout: float = 60.0) -> str:
    """The node's output up to its start-up line ('' if it ended or did not start)."""
    lines = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            return ''
        lines.append(line)
        if "mechanism '" in line:
            return ''.join(lines)
    return ''


def run_mode(context: Any, config: str, mode: str, seconds: float) -> dict[str, np.ndarray]:
    import cog_id_ros

    from .lockstep_plant import LockstepPlant
    mech = cog_id_ros.Mechanism.from_params_file(config)
    inertia = float(cog_id_ros.InverseDynamics(mech).equation_of_motion([math.pi / 2])[0][0, 0])
    extra = [a.format(kp=400 * inertia, kd=40 * inertia) for a in MODES[mode]]
    proc, namespace = start_node(config, mode, extra)
    try:
        if not wait_started(proc):
            raise RuntimeError(f'cog_id_node ({mode}) did not start')
        sim = cog_id_ros.Simulation(mech, H)
        sim.reset(positions=[target(0.0)[0][0] + START_ERROR])
        plant = LockstepPlant(context, namespace, sim, name=f'plant_{mode}')
        try:
            if not plant.connected(feedback=mode != 'feedforward'):
                raise RuntimeError(f'cog_id_node ({mode}) did not connect')
            if mode == 'gravity_compensation':
                out = plant.run(seconds)
                out['setpoints'] = np.full_like(out['positions'], out['positions'][0])
                return out
            return plant.run(seconds, target, feedback=mode != 'feedforward')
        finally:
            plant.close()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


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
    ax.set_title('cog_id_node closed through a simulated paper four-bar, start 0.1 rad off')
    ax.legend(fontsize=8, loc='lower left')
    ax.grid(True, which='both', alpha=0.3)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(output)), exist_ok=True)
    fig.savefig(output, dpi=110)


def summary(results: dict[str, dict[str, np.ndarray]]) -> bool:
    """Print the table; whether computed torque and gravity compensation did their part."""
    print(f"{'mode':<22} {'error at 0 s':>13} {'at 0.5 s':>10} {'max after 0.5 s':>16}")
    ok = True
    for mode, out in results.items():
        error = np.abs(out['setpoints'] - out['positions'])[:, 0]
        late = error[out['time'] >= 0.5]
        print(f'{mode:<22} {error[0]:13.3g} {error[500]:10.3g} {late.max():16.3g}')
        if mode == 'computed_torque':
            ok &= bool(late.max() < 1e-3)
        if mode == 'gravity_compensation':
            ok &= bool(error.max() < 1e-4)
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
        results = {mode: run_mode(context, config, mode, args.seconds) for mode in MODES}
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
