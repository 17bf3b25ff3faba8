"""Fixed joints weld links into rigid bodies: which body each URDF link belongs to, its frame
in the body's, and each body's mass properties (parallel-axis theorem)."""
import numpy as np

from .frames import Frame, rpy_of


class _Bodies:
    """Rigid bodies after merging fixed joints: for each URDF link the link that survives
    (``body``) and the link's frame in the survivor's (``frame``); for each survivor its
    links (``members``, document order)."""

    def __init__(self, robot, body, frame):
        self.body, self.frame = body, frame
        self.members = {}
        for link in robot.links.values():
            self.members.setdefault(body[link.name], []).append(link)

    def attach(self, link, xyz, rpy):
        """(xyz, rpy) of a frame given in ``link``'s frame, in the frame of its body."""
        frame = self.frame[link]
        if frame.identity:
            return [float(x) for x in xyz], [float(x) for x in rpy]
        placed = frame * Frame.of(xyz, rpy)      # + 0.0: no -0.0 in what a user reads
        return ([float(x) + 0.0 for x in placed.translation],
                [float(x) + 0.0 for x in rpy_of(placed.rotation)])


def merge_fixed(robot, base):
    """Each fixed joint welds its child to its parent. A group of links welded together is
    one body named after its top link (the child of a non-fixed joint, or the root), except
    the base link's group, which is named after the base link."""
    body, frame = {}, {}
    for link in robot.walk():
        joint = robot.parent_joint.get(link)
        if joint is None or not joint.welds:
            body[link], frame[link] = link, Frame()
        else:
            body[link] = body[joint.parent]
            frame[link] = frame[joint.parent] * Frame.of(joint.xyz, joint.rpy)
    top = body[base]
    if top != base:
        to_base = frame[base].inverse()
        for link in robot.links:
            if body[link] == top:
                body[link] = base
                frame[link] = Frame() if link == base else to_base * frame[link]
    return _Bodies(robot, body, frame)


def mass_properties(bodies, name):
    """Mass, COG and inertia about the COG of the body ``name``, in its frame."""
    members = bodies.members[name]
    if len(members) == 1:
        link = members[0]
        return link.mass, [float(x) for x in link.com], link.inertia
    placed = []
    for link in members:
        frame = bodies.frame[link.name]
        com = frame.rotation @ np.array(link.com) + frame.translation
        placed.append((link.mass, com, frame.rotation @ link.inertia @ frame.rotation.T))
    mass = sum(m for m, _, _ in placed)
    com = sum(m * c for m, c, _ in placed) / mass if mass > 0.0 else np.zeros(3)
    inertia = np.zeros((3, 3))
    for m, c, tensor in placed:
        d = c - com
        inertia += tensor + m * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return mass, [float(x) for x in com], inertia


def six(inertia):
    """[ixx, iyy, izz, ixy, ixz, iyz] of a 3x3 inertia (symmetrised)."""
    sym = (inertia + inertia.T) / 2.0
    return [float(sym[0, 0]), float(sym[1, 1]), float(sym[2, 2]), float(sym[0, 1]),
            float(sym[0, 2]), float(sym[1, 2])]
