"""The figure of docs/simulation.md's error control: docs/images/simulation_accuracy.png.

    .venv/bin/python bench/figure_simulation_accuracy.py [output.png]

Three panels, each from ``cog_id_ros.Simulation`` at 1 ms steps without efforts:

1. the five-bar (config/five_bar.yaml) falling from its initial pose at rest: the energy
   drift (``Simulation.diagnostics.energy_drift``) relative to the largest kinetic energy,
   for three tolerances; the loosest (1e-2) divides no step and shows what the fixed step
   did near the singular pose at 0.233 s; the run ends where the simulation stops;
2. the same fall at the default tolerance: substeps per step and the closure Jacobian's
   condition number at each step;
3. the paper four-bar (config/paper_four_bar_a.yaml) swinging from 1 rad for 300 s through
   its flat pose (a change point) twice a swing: the energy drift relative to the largest
   kinetic energy, and twice the accumulated error estimate (``total_error_estimate``),
   the bound it is checked against (test/core/test_simulation_accuracy.py).

Prints what it draws (the stop times, the largest drifts).
"""
import os
import sys

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, '..')
sys.path.insert(0, ROOT)
import cog_id_ros  # noqa: E402

OUT = os.path.join(ROOT, 'docs', 'images', 'simulation_accuracy.png')
STEP = 0.001


def fall(name, tolerance, seconds, start=None, every=1):
    """(time, diagnostics) of a run without efforts, until ``seconds`` or a stop; and the
    stop's message (or None)."""
    mech = cog_id_ros.Mechanism.from_params_file(os.path.join(ROOT, 'config', name))
    sim = cog_id_ros.Simulation(mech, STEP, tolerance=tolerance)
    if start is not None:
        sim.reset(*start)
    zeros = [0.0] * len(mech.active_joints)
    seen = [sim.diagnostics]
    for k in range(int(round(seconds / STEP))):
        try:
            sim.step(zeros)
        except cog_id_ros.CogIdError as exc:
            return seen, str(exc)
        if k % every == every - 1:
            seen.append(sim.diagnostics)
    return seen, None


def main(out=OUT):
    fig, axes = plt.subplots(3, 1, figsize=(8.0, 9.5))
    ax = axes[0]
    for tolerance, style in ((1e-2, 'C3-'), (1e-5, 'C1-'), (1e-7, 'C0-')):
        seen, stop = fall('five_bar.yaml', tolerance, 1.0)
        scale = max(d.kinetic_energy for d in seen)
        drift = [max(abs(d.energy_drift) / scale, 1e-16) for d in seen]
        ax.semilogy([d.time for d in seen], drift, style, lw=1.2,
                    label=f'tolerance {tolerance:g}: {seen[-1].total_substeps} substeps, '
                          f'stops at {seen[-1].time:.3f} s')
        print(f'five-bar, tolerance {tolerance:g}: largest drift {max(drift):.3g} of the '
              f'kinetic energy, {seen[-1].divided_steps} steps divided; stop: {stop}')
    ax.axvline(0.233, color='0.6', lw=0.8, ls=':')
    ax.set_ylabel('|energy drift| / largest kinetic energy')
    ax.set_title('five-bar falling without efforts, 1 ms steps: near its singular pose '
                 '(0.233 s) and to the next', fontsize=9)
    ax.legend(fontsize=8, loc='lower right')
    ax = axes[1]
    seen, _ = fall('five_bar.yaml', 1e-7, 1.0)
    times = [d.time for d in seen[1:]]
    ax.semilogy(times, [d.substeps for d in seen[1:]], 'C0.-', ms=3, lw=0.8,
                label='substeps of the step')
    ax.semilogy(times, [d.condition_number for d in seen[1:]], 'C2-', lw=1.0,
                label='closure Jacobian condition number')
    ax.axvline(0.233, color='0.6', lw=0.8, ls=':')
    ax.set_title('the same fall at the default tolerance (1e-7)', fontsize=9)
    ax.legend(fontsize=8, loc='upper left')
    ax = axes[2]
    seen, stop = fall('paper_four_bar_a.yaml', 1e-7, 300.0, ([1.0], [0.0]), every=100)
    scale = max(d.kinetic_energy for d in seen)
    ax.semilogy([d.time for d in seen], [max(abs(d.energy_drift) / scale, 1e-16) for d in seen],
                'C0-', lw=1.0, label='|energy drift| / largest kinetic energy')
    ax.semilogy([d.time for d in seen], [max(2.0 * d.total_error_estimate, 1e-16)
                                         for d in seen], 'C3--', lw=1.0,
                label='2 x accumulated error estimate (the bound checked)')
    ax.set_xlabel('simulated time (s)')
    ax.set_title(f'paper four-bar swinging from 1 rad through its flat pose: '
                 f'{seen[-1].divided_steps} steps divided in {seen[-1].time:.0f} s, '
                 f'{"no stop" if stop is None else "stopped"}', fontsize=9)
    ax.legend(fontsize=8, loc='lower right')
    print(f'paper four-bar: drift {seen[-1].energy_drift / scale:.3g} of the kinetic energy, '
          f'accumulated estimate {seen[-1].total_error_estimate:.3g}, '
          f'{seen[-1].divided_steps} steps divided, {seen[-1].inaccurate_substeps} substeps '
          f'passed with their rounding reported; stop: {stop}')
    for a in axes:
        a.grid(True, which='both', lw=0.3, alpha=0.5)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f'wrote {out}')


if __name__ == '__main__':
    main(*sys.argv[1:])
