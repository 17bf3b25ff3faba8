"""Picture of a mechanism at a pose, for ``cog_id_inspect --plot``.

Links are drawn between the world positions of their joints' attachment frames (a polygon
for a link with three or more), joints as markers at their parent attachment (circle:
revolute, square: prismatic, diamond: spherical, universal, fixed; red: active), the
loop-closing joints ringed, COGs as dots whose area is proportional to the mass, the base
link's attachment points in black. A planar mechanism (every revolute axis parallel, every
prismatic axis perpendicular to them, no spherical or universal joint) is drawn in its
plane, with the direction against gravity up where gravity lies in the plane; any other in
3-D. Both with equal scales on the axes. Snapshots of a motion are drawn thin and faded
behind the pose.

Matplotlib's object API on the Agg canvas, like :mod:`cog_id_ros.offline.plotting`: no
pyplot, no display, no global backend switch.
"""

import numpy as np

from ..core.kinematics import joints
from ..core.kinematics import kinematics as kin
from ..core.linalg import spatial as sp
from . import figure_text, idle_spin_marks, joint_space_marks

#: axes closer to parallel (or perpendicular) than this (sine or cosine) count as such
PLANAR_TOLERANCE = 1e-6
#: points of one link closer than this fraction of the mechanism's size are one point
SAME_POINT = 1e-6
#: margin around the drawing, as a fraction of its size
PAD = 0.12
#: and more on the right of a 2-D drawing, where the names are written
RIGHT = 0.08
#: resolution of the picture, dots per inch (the figure is laid out at it too)
DPI = 90
#: joints and links are named on the picture up to these counts
MAX_JOINT_LABELS = 12
MAX_LINK_LABELS = 8

#: names are drawn above every other artist of the axes, on a light box: the joint markers
#: (zorder 6-7) and COG dots (5) used to be drawn over them. 1000, not just above 7:
#: mplot3d renumbers the collections and patches of 3-D axes by depth, one zorder each
#: from about 1 upwards, so a small number could fall below a marker there
LABEL_ZORDER = 1000
LABEL_BOX = {'boxstyle': 'round,pad=0.15', 'facecolor': 'white', 'edgecolor': 'none',
             'alpha': 0.75}
#: offsets (points) of a joint's name and a link's name from the joint and the COG: clear
#: of the largest marker there (the loop-closing ring, 9 points in radius with its edge;
#: the heaviest COG dot, 7), so the name's box does not cover it
JOINT_LABEL_OFFSET = (10, 7)
LINK_LABEL_OFFSET = (9, -13)

ACTIVE_COLOR = '#d62728'
CLOSING_COLOR = '#ff7f0e'
BASE_COLOR = '#333333'
PLATFORM_COLOR = '#5f7f9f'
#: link colours: matplotlib's tab10 without its red (the active joints are red)
PALETTE = ('#1f77b4', '#ff7f0e', '#2ca02c', '#9467bd', '#8c564b', '#e377c2', '#7f7f7f',
           '#bcbd22', '#17becf')


def link_frames(mech, coordinates):
    """The links' frames (a :class:`kinematics.Frames`) at every solver coordinate:
    mechanism.joints, then the hidden ones of the spherical and universal joints in the
    spanning tree (``mechanism.assembled_coordinates`` at the assembled pose). The joints'
    positions alone do not place a link reached through such a joint."""
    n = mech.n_coordinates
    if len(coordinates) != n:
        raise ValueError(f'{mech.name}: expected all {n} solver coordinates (mechanism.'
                         f'assembled_coordinates; {n - len(mech.joints)} hidden ones of '
                         f'joints in the spanning tree), got {len(coordinates)}: for a pose '
                         f'the solver reached, use frames_from_cog_poses')
    return kin.forward_kinematics(mech.model, [float(x) for x in coordinates], sp.ScalarOps)


def frames_from_cog_poses(mech, positions, rotations):
    """The links' frames from ``InverseDynamics.cog_poses`` of one sample: COG positions
    (n_links, 3) and link rotations (n_links, 3, 3) of the moving links; the frame origin
    is the COG less the rotated ``link_com``."""
    frames = kin.Frames()
    frames.rot, frames.pos, frames.xi = [], [], []
    for cog, rotation, com in zip(np.asarray(positions, float), np.asarray(rotations, float),
                                  mech.link_com):
        frames.rot.append(tuple(float(x) for x in rotation.reshape(9)))
        frames.pos.append(tuple(float(x) for x in cog - rotation @ np.asarray(com, float)))
    return frames


class Pose:
    """World geometry of a mechanism at a pose: ``where`` is every solver coordinate
    (:func:`link_frames`; mechanism.joints order, then the hidden ones) or the links'
    frames (a :class:`kinematics.Frames`, e.g. :func:`frames_from_cog_poses`).

    ``joints``: per joint (with a coordinate, then the spherical, universal and fixed ones)
    a dict with name, kind (its kind object, core/kinematics/joints.py: how it is drawn), active,
    closing, parent_point, child_point, axes (world unit vectors). ``links``: per moving
    link (name, attachment points (k, 3), cog (3,), mass); the solver's own massless links
    (the cross of a universal joint in the tree) are not
    among them. ``base_points``: (k, 3) attachment points on the base link.
    """

    def __init__(self, mech, where):
        frames = where if isinstance(where, kin.Frames) else link_frames(mech, where)
        closing = {lp.name for lp in mech.model.loops}
        active = set(mech.active_joints)
        specs = list(mech.joint_specs) + list(getattr(mech, 'closure_specs', ()))
        points = {k: [] for k in range(len(mech.links))}
        points[kin.BASE] = []
        self.joints = []
        for spec in specs:
            parent_point, child_point = self._attachments(frames, spec)
            points[spec.parent].append(parent_point)
            points[spec.child].append(child_point)
            rot = kin.vector_to_base(frames, spec.parent, sp.mat_vec(
                sp.rpy_matrix(spec.parent_rpy), spec.kind.axis))
            axes = [np.array(rot)] if spec.kind.draws_axis else []
            self.joints.append(dict(name=spec.name, kind=spec.kind,
                                    active=spec.name in active, closing=spec.name in closing,
                                    parent_point=parent_point, child_point=child_point,
                                    axes=axes))
        every = np.array([p for pts in points.values() for p in pts] or [np.zeros(3)])
        self.size = float(np.ptp(every, axis=0).max()) if len(every) > 1 else 0.0
        self.size = self.size or 1.0
        self.links = []
        for k, name in enumerate(mech.links):
            cog = np.array(kin.point_to_base(frames, k, mech.link_com[k]))
            self.links.append((name, _distinct(points[k], SAME_POINT * self.size), cog,
                               float(mech.link_mass[k])))
        self.base_points = _distinct(points[kin.BASE], SAME_POINT * self.size)

    @staticmethod
    def _attachments(frames, spec):
        """World points of the joint frame on its parent and on its child link (they
        coincide but for a prismatic joint, where they are q apart along the axis)."""
        parent_point = np.array(kin.point_to_base(frames, spec.parent, spec.parent_xyz))
        child_point = np.array(kin.point_to_base(frames, spec.child, spec.child_xyz))
        return parent_point, child_point

    def all_points(self):
        pts = [j['parent_point'] for j in self.joints] + [j['child_point'] for j in self.joints]
        pts += [cog for _, _, cog, _ in self.links]
        return np.array(pts)


def _distinct(points, tolerance):
    """The points, those within ``tolerance`` of an earlier one dropped, as (k, 3)."""
    kept = []
    for p in points:
        p = np.asarray(p, float)
        if all(np.linalg.norm(p - other) > tolerance for other in kept):
            kept.append(p)
    return np.array(kept).reshape(-1, 3)


def planar_normal(mech, pose):
    """The normal of the plane a planar mechanism moves in, or None for a spatial one:
    every revolute axis parallel to it and every prismatic axis perpendicular, no
    spherical or universal joint (each kind says where its axis lies in a planar mechanism,
    ``planar_axis``). Without a revolute joint, the plane of the points."""
    if any(j['kind'].planar_axis is None for j in pose.joints):
        return None
    revolute = [j['axes'][0] for j in pose.joints if j['kind'].planar_axis == 'normal']
    prismatic = [j['axes'][0] for j in pose.joints if j['kind'].planar_axis == 'in_plane']
    if revolute:
        normal = revolute[0] / np.linalg.norm(revolute[0])
    else:
        points = pose.all_points()
        centred = points - points.mean(axis=0)
        if len(points) < 3:
            return None
        _, s, vt = np.linalg.svd(centred)
        if s[-1] > PLANAR_TOLERANCE * max(s[0], 1e-300):
            return None
        normal = vt[-1]
    if any(np.linalg.norm(np.cross(a, normal)) > PLANAR_TOLERANCE for a in revolute):
        return None
    if any(abs(float(np.dot(a, normal))) > PLANAR_TOLERANCE for a in prismatic):
        return None
    return normal


WORLD = np.eye(3)
AXIS_NAMES = ('x', 'y', 'z')


def plane_axes(normal, gravity):
    """(horizontal, up, labels) of the drawing plane: up against gravity where gravity has
    a component in the plane, each a world axis when the plane allows."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    g = np.asarray(gravity, float)
    in_plane = g - np.dot(g, n) * n
    if np.linalg.norm(in_plane) > 1e-9 * max(np.linalg.norm(g), 1e-300):
        up = -in_plane / np.linalg.norm(in_plane)
    else:          # gravity along the normal, or none: the in-plane world axis last in xyz
        k = max((k for k in range(3) if abs(n[k]) < 0.5), default=2)
        up = WORLD[k] - np.dot(WORLD[k], n) * n
        up /= np.linalg.norm(up)
    across = np.cross(up, n)
    k = int(np.argmax(np.abs(across)))
    horizontal = across * np.sign(across[k])
    labels = [_axis_label(horizontal), _axis_label(up)]
    return horizontal, up, labels


def _axis_label(v):
    k = int(np.argmax(np.abs(v)))
    if abs(abs(v[k]) - 1.0) < 1e-9:
        return f"{'-' if v[k] < 0 else ''}{AXIS_NAMES[k]} [m]"
    return '[' + ', '.join(f'{c:.2f}' for c in v) + '] [m]'


def _ordered(points, normal=None):
    """Points of a polygon in angular order about their centroid, in their best-fit plane."""
    centred = points - points.mean(axis=0)
    if normal is None:
        _, _, vt = np.linalg.svd(centred)
        e1, e2 = vt[0], vt[1]
    else:
        e1 = centred[int(np.argmax(np.linalg.norm(centred, axis=1)))]
        e1 = e1 - np.dot(e1, normal) * normal
        e1 = e1 / (np.linalg.norm(e1) or 1.0)
        e2 = np.cross(normal, e1)
    angles = np.arctan2(centred @ e2, centred @ e1)
    return points[np.argsort(angles)]


def draw_mechanism(path, mech, q, snapshots=(), fmt='png', title=None, subtitle=None,
                   warning=None):
    """Draw ``mech`` at pose ``q`` into ``path``: every solver coordinate (mechanism.joints
    order, then the hidden ones: ``mechanism.assembled_coordinates``) or the links' frames
    (:class:`Pose`).

    ``snapshots``: [(time, q)] drawn faded behind (earlier lighter), each ``q`` as above.
    ``fmt``: the image format (``path`` may be a temporary name). ``warning``: a line shown
    in red under the title."""
    figure = mechanism_figure(mech, q, snapshots, title, subtitle, warning)
    figure.savefig(path, format=fmt, dpi=DPI)


def mechanism_figure(mech, q, snapshots=(), title=None, subtitle=None, warning=None):
    """The matplotlib Figure :func:`draw_mechanism` saves (arguments as there)."""
    from matplotlib.figure import Figure

    pose = Pose(mech, q)
    ghosts = [(t, Pose(mech, qs)) for t, qs in snapshots]
    normal = planar_normal(mech, pose)
    if normal is not None and all(planar_normal(mech, g) is not None for _, g in ghosts):
        horizontal, up, labels = plane_axes(normal, mech.gravity)
        basis = np.array([horizontal, up])
        points = np.vstack([g.all_points() for g in [pose] + [g for _, g in ghosts]])
        extent = np.ptp(points @ basis.T, axis=0)
        extent = extent + np.array([2.0 * PAD + RIGHT, 2.0 * PAD]) * max(float(extent.max()),
                                                                         1e-9)   # as finish()
        height = min(max(6.6 * extent[1] / extent[0], 2.0), 6.4)   # the axes, in inches
        fig = Figure(figsize=(8.0, height + 2.4), dpi=DPI, layout='constrained')
        ax = fig.add_subplot()
        view = _View2D(ax, basis, normal)
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        kind = 'planar'
    else:
        fig = Figure(figsize=(8.0, 7.0), dpi=DPI, layout='constrained')
        ax = fig.add_subplot(projection='3d')
        view = _View3D(ax)
        ax.set_xlabel('x [m]')
        ax.set_ylabel('y [m]')
        ax.set_zlabel('z [m]')
        kind = 'spatial'
    colors = link_colors(mech, pose)
    for k, (_, ghost) in enumerate(ghosts):
        alpha = 0.12 + 0.3 * (k + 1) / len(ghosts)
        _draw_links(view, ghost, colors, alpha=alpha, width=1.5, fill=False)
    _draw_base(view, pose)
    _draw_links(view, pose, colors)
    _draw_cogs(view, pose, colors)
    _draw_joints(view, pose)
    idle_spin_marks.draw(view, pose, mech)
    joint_space_marks.draw(view, pose, mech)
    labels = _label(view, mech, pose, colors)
    view.finish([pose.all_points()] + [g.all_points() for _, g in ghosts]
                + [pose.base_points])
    handles = (_legend_handles(mech, pose, ghosts) + idle_spin_marks.legend(mech)
               + joint_space_marks.legend(mech))
    fig.legend(handles=handles, loc='outside lower center', ncols=3, fontsize=8)
    loops = len(mech.model.loops)
    heading = title or (f"{mech.name}: {mech.dof} DOF, {len(mech.links)} links, {loops} "
                        f"loop{'' if loops == 1 else 's'} ({kind}), assembled pose")
    # wrapped to the figure's width: a long name or file name was cut at both edges
    figure_text.suptitle(fig, heading + (f'\n{subtitle}' if subtitle else ''), 11)
    if warning:
        figure_text.axes_title(fig, ax, warning, 9, color=ACTIVE_COLOR)
    _separate(fig, view, labels)
    return fig


def _separate(fig, view, labels):
    """Move a name away from its point (up when it is above it, down when below) until its
    box is clear of the boxes of the names placed before it: names of points close
    together (a joint and a closing joint beside it, links whose COGs nearly coincide)
    were written over one another."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    if len(labels) < 2:
        return
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw_without_rendering()                 # the layout, hence where the names are
    # and no second layout when saving: it would move the axes a little (constrained
    # layout run twice does not land on the same place), and the names with them
    fig.set_layout_engine('none')
    gap = 1.0 * fig.dpi / 72.0                   # pixels between two boxes
    placed = []
    for label in labels:
        box = label.get_bbox_patch().get_window_extent(renderer)
        up = view.offset(label)[1] >= 0
        for _ in range(len(placed) + 1):
            hit = next((b for b in placed if b.overlaps(box)), None)
            if hit is None:
                break
            move = hit.y1 - box.y0 + gap if up else hit.y0 - box.y1 - gap
            box = box.translated(0.0, move)
            view.shift(label, 72.0 * move / fig.dpi)
        placed.append(box)


def _label(view, mech, pose, colors):
    """Name the joints (those at one point together) and the links, on small mechanisms;
    returns the names' Text artists."""
    drawn = []
    if len(pose.joints) <= MAX_JOINT_LABELS:
        for point, names in _joint_groups(pose):
            drawn.append(view.text(point, '/'.join(names), fontsize=8, color='#444444',
                                   offset=JOINT_LABEL_OFFSET))
    if len(mech.links) <= MAX_LINK_LABELS:
        labels = []          # links drawn over one another are named together
        for (name, points, cog, _), color in zip(pose.links, colors):
            if len(_drawn(points, cog, pose.size)) < 2:
                continue
            for label in labels:
                if np.linalg.norm(label[0] - cog) <= SAME_POINT * pose.size:
                    label[1].append(name)
                    break
            else:
                labels.append((cog, [name], color))
        for cog, names, color in labels:
            drawn.append(view.text(cog, '/'.join(names), fontsize=8, color=color,
                                   fontweight='bold', offset=LINK_LABEL_OFFSET))
    return drawn


def _legend_handles(mech, pose, ghosts):
    from matplotlib.lines import Line2D
    handles = [
        Line2D([], [], color='#4c72b0', lw=4, label='link (between its joints)'),
        Line2D([], [], color=BASE_COLOR, lw=0, marker='^', markersize=9,
               label=f'base ({mech.base_link})'),
        Line2D([], [], color='black', lw=0, marker='o', markerfacecolor='white',
               markersize=8, label='passive joint'),
        Line2D([], [], color='black', lw=0, marker='o', markerfacecolor=ACTIVE_COLOR,
               markersize=9, label=joint_space_marks.active_label(mech)),
        Line2D([], [], color=CLOSING_COLOR, lw=0, marker='o', markerfacecolor='none',
               markeredgewidth=2.5, markersize=14, label='loop-closing joint'),
        Line2D([], [], color='#4c72b0', lw=0, marker='o', markeredgecolor='black',
               markersize=7, label='COG (area ~ mass)'),
    ]
    shown = {j['kind'].name for j in pose.joints}
    legends = {kind.legend: kind.marker for kind in joints.KINDS.values()
               if kind.name in shown and kind.legend}
    for label, marker in legends.items():
        handles.append(Line2D([], [], color='black', lw=0, marker=marker,
                              markerfacecolor='white', markersize=7 if marker == 'D' else 8,
                              label=label))
    if ghosts:
        handles.append(Line2D([], [], color='gray', lw=1.5, alpha=0.4,
                              label='snapshots (lighter: earlier)\nt = '
                              + ', '.join(f'{t:.3g}' for t, _ in ghosts) + ' s'))
    return handles


class _View2D:
    def __init__(self, ax, basis, normal):
        self.ax, self.basis, self.normal = ax, basis, normal

    def xy(self, points):
        return np.atleast_2d(points) @ self.basis.T

    def line(self, points, **kw):
        p = self.xy(points)
        self.ax.plot(p[:, 0], p[:, 1], **kw)

    def polygon(self, points, color, alpha):
        from matplotlib.patches import Polygon
        p = self.xy(_ordered(points, self.normal))
        self.ax.add_patch(Polygon(p, closed=True, facecolor=color, alpha=alpha, lw=0))

    def scatter(self, points, **kw):
        p = self.xy(points)
        self.ax.scatter(p[:, 0], p[:, 1], **kw)

    def text(self, point, text, offset=(4, 4), **kw):
        p = self.xy(point)[0]
        return self.ax.annotate(text, p, xytext=offset, textcoords='offset points',
                                zorder=LABEL_ZORDER, bbox=LABEL_BOX, **kw)

    @staticmethod
    def offset(label):
        """A name's offset from its point, points."""
        return label.xyann

    @staticmethod
    def shift(label, up):
        """Move a name ``up`` points (down when negative)."""
        x, y = label.xyann
        label.xyann = (x, y + up)

    def finish(self, point_sets):
        pts = self.xy(np.vstack([p for p in point_sets if len(p)]))
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = PAD * max(float((hi - lo).max()), 1e-9)
        self.ax.set_xlim(lo[0] - pad, hi[0] + pad + RIGHT * pad / PAD)   # room for labels
        self.ax.set_ylim(lo[1] - pad, hi[1] + pad)
        self.ax.set_aspect('equal', adjustable='box')
        self.ax.grid(True, lw=0.4, alpha=0.5)


class _View3D:
    def __init__(self, ax):
        self.ax = ax

    def line(self, points, **kw):
        p = np.atleast_2d(points)
        self.ax.plot(p[:, 0], p[:, 1], p[:, 2], **kw)

    def polygon(self, points, color, alpha):
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection
        p = _ordered(points)
        self.ax.add_collection3d(Poly3DCollection([p], facecolor=color, alpha=alpha,
                                                  edgecolor='none'))

    def scatter(self, points, **kw):
        p = np.atleast_2d(points)
        self.ax.scatter(p[:, 0], p[:, 1], p[:, 2], depthshade=False, **kw)

    def text(self, point, text, offset=(4, 4), **kw):
        x, y, z = np.asarray(point, float)
        label = self.ax.text(x, y, z, text, ha='left', va='bottom', zorder=LABEL_ZORDER,
                             bbox=LABEL_BOX, **kw)
        label.offset = tuple(offset)
        self._place(label)
        return label

    def _place(self, label):
        # a 3-D text is drawn at its projected point through its transform: the data
        # transform shifted by ``offset`` points puts it beside the marker, like annotate
        from matplotlib.transforms import offset_copy
        label.set_transform(offset_copy(self.ax.transData, fig=self.ax.figure,
                                        x=label.offset[0], y=label.offset[1], units='points'))

    @staticmethod
    def offset(label):
        """A name's offset from its point, points."""
        return label.offset

    def shift(self, label, up):
        """Move a name ``up`` points (down when negative)."""
        label.offset = (label.offset[0], label.offset[1] + up)
        self._place(label)

    def finish(self, point_sets):
        pts = np.vstack([p for p in point_sets if len(p)])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre, half = (lo + hi) / 2.0, 0.55 * max(float((hi - lo).max()), 1e-9)
        self.ax.set_xlim(centre[0] - half, centre[0] + half)
        self.ax.set_ylim(centre[1] - half, centre[1] + half)
        self.ax.set_zlim(centre[2] - half, centre[2] + half)
        self.ax.set_box_aspect((1.0, 1.0, 1.0))
        self.ax.view_init(elev=22.0, azim=-60.0)


def _drawn(points, cog, size):
    """A link's points as drawn: its attachment points, and its COG when it hangs from one."""
    if len(points) == 1 and np.linalg.norm(cog - points[0]) > SAME_POINT * size:
        return np.vstack([points, cog])
    return points


def link_colors(mech, pose):
    """A colour per link. Up to len(PALETTE) drawn links (two points or more), one each;
    beyond, one hue per branch of the spanning tree from the base (a leg of a parallel
    robot), dark and light in turn along it, and a neutral one for a link where two loops
    or more close (a platform). Red is kept for the active joints."""
    from matplotlib import colormaps
    drawn = [len(_drawn(points, cog, pose.size)) >= 2 for _, points, cog, _ in pose.links]
    if sum(drawn) <= len(PALETTE):
        order = np.cumsum(drawn) - 1
        return [PALETTE[int(k) % len(PALETTE)] for k in order]
    model = mech.model
    pairs = colormaps['tab20']
    hues = [h for h in range(10) if h != 3]          # tab20 pair 3 is red
    closures = {}
    for loop in model.loops:
        for link in (loop.parent, loop.child):
            closures[link] = closures.get(link, 0) + 1
    branch, count, roots = {}, {}, 0
    colors = [None] * len(mech.links)
    for edge in model.edges:                         # breadth-first: parents come first
        link = edge.child
        if edge.parent == kin.BASE:
            branch[link], roots = roots, roots + 1
        else:
            branch[link] = branch[edge.parent]
        if link >= len(mech.links) or not drawn[link]:    # (a universal joint's cross)
            continue
        if closures.get(link, 0) >= 2:
            colors[link] = PLATFORM_COLOR
            continue
        hue = hues[branch[link] % len(hues)]
        shade = count.get(branch[link], 0)
        count[branch[link]] = shade + 1
        colors[link] = pairs(2 * hue + shade % 2)
    return [c if c is not None else PALETTE[0] for c in colors]


def _draw_links(view, pose, colors, alpha=1.0, width=None, fill=True):
    width = width or (5.0 if isinstance(view, _View2D) else 3.5)
    for (_, points, cog, _), color in zip(pose.links, colors):
        points = _drawn(points, cog, pose.size)
        if len(points) == 2:
            view.line(points, color=color, lw=width, alpha=alpha, solid_capstyle='round')
        elif len(points) >= 3:
            ring = _ordered(points, getattr(view, 'normal', None))
            view.line(np.vstack([ring, ring[:1]]), color=color, lw=width * 0.7, alpha=alpha,
                      solid_joinstyle='round')
            if fill:
                view.polygon(points, color, 0.25 * alpha)
    for j in pose.joints:   # a prismatic joint's stroke: parent to child attachment (apart)
        if not j['kind'].origins_coincide:
            view.line(np.vstack([j['parent_point'], j['child_point']]), color='#555555',
                      lw=1.2, ls=':', alpha=alpha)


def _draw_base(view, pose):
    """The base link's attachment points (fixed: drawn once, not per snapshot)."""
    base = pose.base_points
    if len(base) >= 3:
        ring = _ordered(base, getattr(view, 'normal', None))
        view.line(np.vstack([ring, ring[:1]]), color=BASE_COLOR, lw=1.5, ls='--')
        view.polygon(base, '#999999', 0.25)
    elif len(base) == 2:
        view.line(base, color=BASE_COLOR, lw=1.5, ls='--')
    if len(base):
        view.scatter(base, marker='^', s=110, color=BASE_COLOR, zorder=3)


def _joint_groups(pose):
    """[(point, names)] of the joints, those at one point together (a spherical joint
    written as three revolute ones, a universal joint as two)."""
    groups = []
    for j in pose.joints:
        for point, names in groups:
            if np.linalg.norm(point - j['parent_point']) <= SAME_POINT * pose.size:
                names.append(j['name'])
                break
        else:
            groups.append((j['parent_point'], [j['name']]))
    return groups


def _draw_cogs(view, pose, colors):
    heaviest = max((mass for _, _, _, mass in pose.links), default=0.0)
    for (_, _, cog, mass), color in zip(pose.links, colors):
        if mass > 0.0 and heaviest > 0.0:
            view.scatter(cog, s=15.0 + 160.0 * mass / heaviest, color=color,
                         edgecolors='black', linewidths=0.8, zorder=5)


def _draw_joints(view, pose):
    for j in pose.joints:
        marker = j['kind'].marker
        face = ACTIVE_COLOR if j['active'] else 'white'
        size = 80 if j['active'] else 45
        view.scatter(j['parent_point'], marker=marker, s=size, facecolors=face,
                     edgecolors='black', linewidths=1.0, zorder=6)
        if j['closing']:
            view.scatter(j['parent_point'], marker='o', s=260, facecolors='none',
                         edgecolors=CLOSING_COLOR, linewidths=2.5, zorder=7)


def figure_kind(mech, q):
    """'planar' or 'spatial': how :func:`draw_mechanism` draws ``mech`` at ``q`` (as
    there)."""
    return 'planar' if planar_normal(mech, Pose(mech, q)) is not None else 'spatial'
