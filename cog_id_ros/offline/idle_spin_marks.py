"""What ``cog_id_inspect --plot`` adds to the picture for idle spins and locked joints.

A set of links that spins idly about its own axis (core/model/idle_spins.py: a rod between two
balls, two halves welded into one rod, a body between coaxial joints) is drawn with a
dashed magenta line along its axis, through the joints it hangs on; each locked joint
(``mechanism.locked_joints``, or the one ``idle_spins: lock`` chose) with a dark cross on its
marker. Drawn over the mechanism by :func:`draw`; :func:`legend` gives the legend entries.
"""

import numpy as np

SPIN_COLOR = '#e6007e'
LOCK_COLOR = '#222222'


def _joint_points(pose):
    return {j['name']: j['parent_point'] for j in pose.joints}


def draw(view, pose, mech):
    """The spins' axes and the locked joints' crosses on ``view`` (mechanism_plot's)."""
    points = _joint_points(pose)
    for spin in getattr(mech, 'idle_spin_sets', ()):
        ends = [points[name] for name in spin['ends'] if name in points]
        if len(ends) >= 2:
            axis = np.array(ends)
            span = axis[-1] - axis[0]
            if np.linalg.norm(span) > 0.0:      # a little beyond the two ends
                axis = np.vstack([axis[0] - 0.3 * span, axis[-1] + 0.3 * span])
            view.line(axis, color=SPIN_COLOR, lw=2.5, ls='--', alpha=0.95, zorder=9)
    locked = [points[name] for name in mech.locked_joints if name in points]
    if locked:
        view.scatter(np.array(locked), marker='X', s=90, color=LOCK_COLOR, zorder=8)


def legend(mech):
    """Legend handles for what :func:`draw` drew (none where it drew nothing)."""
    from matplotlib.lines import Line2D
    handles = []
    if getattr(mech, 'idle_spin_sets', ()):
        handles.append(Line2D([], [], color=SPIN_COLOR, lw=2.0, ls='--',
                              label='idle spin (axis of a set that spins)'))
    if mech.locked_joints:
        handles.append(Line2D([], [], color=LOCK_COLOR, lw=0, marker='X', markersize=9,
                              label='locked joint'))
    return handles
