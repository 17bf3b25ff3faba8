"""What ``cog_id_inspect --plot`` adds to the picture of a mechanism that names
``mechanism.joint_space``: both spaces labelled.

The motors (``mechanism.active_joints``, actuator space) keep the red marker of an active
joint, and the legend calls them the actuator space; each joint of the joint space (the
joints a controller commands; a motor may be one) gets a blue hexagonal ring and a legend
entry naming the joint space. Drawn over the mechanism by :func:`draw`; :func:`legend`
gives the legend entries, :func:`active_label` the active joints' legend text.
"""

JOINT_SPACE_COLOR = '#0b4f9c'


def active_label(mech):
    """The legend text of the active joints' marker."""
    if getattr(mech, 'joint_space', None):
        return 'actuator space: motor (active joint)'
    return 'active joint'


def draw(view, pose, mech):
    """A ring around each joint of the joint space on ``view`` (mechanism_plot's)."""
    names = set(getattr(mech, 'joint_space', ()) or ())
    for j in pose.joints:
        if j['name'] in names:
            view.scatter(j['parent_point'], marker='h', s=420, facecolors='none',
                         edgecolors=JOINT_SPACE_COLOR, linewidths=2.2, zorder=8)


def legend(mech):
    """Legend handles for what :func:`draw` drew (none without a joint space)."""
    from matplotlib.lines import Line2D
    names = list(getattr(mech, 'joint_space', ()) or ())
    if not names:
        return []
    shown = ', '.join(names[:4]) + (f' +{len(names) - 4}' if len(names) > 4 else '')
    return [Line2D([], [], color=JOINT_SPACE_COLOR, lw=0, marker='h', markerfacecolor='none',
                   markeredgewidth=2.2, markersize=15,
                   label=f'joint space (commanded): {shown}')]
