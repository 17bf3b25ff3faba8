"""Joint kinds (core/kinematics/joints.py): a new kind is one class and its registration.

The toy kind of docs/adding_a_joint_kind.md, a helical (screw) joint, is written here as
that page says, registered, loaded from parameters and solved; its torques are checked
against the equations of motion written out by hand from what a screw does (rotation q
about the axis, translation pitch * q along it), not against the solver. And the names of
the kinds are spelled in few modules of the package: everything else asks the kind.
"""
import ast
import math
import pathlib

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.core.errors import MechanismConfigError
from cog_id_ros.core.kinematics import joints
from cog_id_ros.core.linalg import spatial as sp
from cog_id_ros.offline import inspect_pose, mechanism_plot

BACKENDS = ('reference', 'python')
GRAVITY = 9.81
PACKAGE = pathlib.Path(cog_id_ros.__file__).parent


# --- the toy kind, as docs/adding_a_joint_kind.md writes it ---------------------------------

class Helical(joints.Revolute):
    """A screw: rotation q about ``axis`` and translation pitch * q along it (m per rad).

    M(q) = (Rot(axis, q), pitch q axis): the rotation of a revolute joint, and in the
    tree t_L gains pitch (sign q) R_A axis, where the loop's moved attachment gains
    pitch q axis_p; S = (axis, origin x axis + pitch axis). The six closure rows, the
    bias and a step of ``step`` rad are a revolute joint's.
    """

    name = coordinate_type = 'helical'
    aliases = ()
    wraps = False                  # q + 2 pi is another pose: the nut moved on
    origins_coincide = False       # the nut's origin travels along the axis
    parameters = joints.Revolute.parameters + ('pitch',)
    marker, legend, planar_axis = 'h', 'helical joint', None

    def __init__(self, axis=(0.0, 0.0, 1.0), pitch=0.0):
        super().__init__(axis)
        self.pitch = pitch

    @classmethod
    def read(cls, r, prefix):
        return cls(joints.unit_axis(r, prefix + 'axis', (0.0, 0.0, 1.0)),
                   r.number(prefix + 'pitch', required=True))

    def local_pose(self, e, qj, ops):
        r_local, t_local = super().local_pose(e, qj, ops)
        return r_local, sp.add_scaled(t_local, e.axis_p, e.sign * self.pitch * qj)

    def twist(self, axis, origin):
        return (axis, sp.add_scaled(sp.cross(origin, axis), axis, self.pitch))

    def moved_attachment(self, lp, q, ops):
        r_moved, t_moved = super().moved_attachment(lp, q, ops)
        return r_moved, sp.add_scaled(t_moved, lp.axis_p, self.pitch * q[lp.joint])


@pytest.fixture
def helical(monkeypatch):
    """Helical registered for one test (the registry as it was afterwards)."""
    monkeypatch.setattr(joints, 'KINDS', dict(joints.KINDS))
    joints.register(Helical)
    return Helical


# --- mechanisms with a screw ----------------------------------------------------------------

PITCH = 0.02                        # m per rad
AXIS_RPY = (0.4, -0.7, 0.2)         # the screw's axis leans: gravity turns the nut
COM = (0.15, -0.05, 0.1)            # off the axis
MASS = 1.3
INERTIA = (0.02, 0.03, 0.025, 0.004, -0.002, 0.001)     # ixx iyy izz ixy ixz iyz


def serial_screw():
    """A nut on a fixed screw, driven by the screw joint itself (a tree joint)."""
    return {
        'mechanism.links': ['nut'], 'mechanism.joints': ['thread'],
        'mechanism.active_joints': ['thread'], 'mechanism.initial_positions': [0.3],
        'mechanism.gravity': [0.0, 0.0, -GRAVITY],
        'links.nut.mass': MASS, 'links.nut.com': list(COM), 'links.nut.inertia': list(INERTIA),
        'joints.thread.type': 'helical', 'joints.thread.parent': 'ground',
        'joints.thread.child': 'nut', 'joints.thread.parent_xyz': [0.1, 0.2, 0.3],
        'joints.thread.parent_rpy': list(AXIS_RPY), 'joints.thread.pitch': PITCH,
    }


SCREW_INERTIA = 0.05                # kg m^2 about the screw's axis
NUT_MASS = 2.0


def screw_jack():
    """A screw turned by a motor (revolute, active) drives a nut that slides on a guide
    (prismatic): the thread between them closes the loop."""
    return {
        'mechanism.links': ['screw', 'nut'],
        'mechanism.joints': ['motor', 'guide', 'thread'],
        'mechanism.active_joints': ['motor'],
        'mechanism.initial_positions': [0.3, -PITCH * 0.3, -0.3],
        'mechanism.gravity': [0.0, 0.0, -GRAVITY],
        'links.screw.mass': 0.5, 'links.screw.inertia': [0.03, 0.03, SCREW_INERTIA, 0, 0, 0],
        'links.nut.mass': NUT_MASS, 'links.nut.inertia': [0.003, 0.004, 0.005, 0, 0, 0],
        'joints.motor.type': 'revolute', 'joints.motor.parent': 'ground',
        'joints.motor.child': 'screw',
        'joints.guide.type': 'prismatic', 'joints.guide.parent': 'ground',
        'joints.guide.child': 'nut',
        'joints.thread.type': 'helical', 'joints.thread.parent': 'screw',
        'joints.thread.child': 'nut', 'joints.thread.pitch': PITCH,
    }


def motion(start, n=7):
    t = np.linspace(0.0, 1.5, n)
    return start + 0.8 * np.sin(2.0 * t), 1.6 * np.cos(2.0 * t), -3.2 * np.sin(2.0 * t)


def _rpy(rpy):
    (cr, sr), (cp, spi), (cy, sy) = ((math.cos(a), math.sin(a)) for a in rpy)
    return (np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @
            np.array([[cp, 0, spi], [0, 1, 0], [-spi, 0, cp]]) @
            np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]))


def _rotation(axis, angle):
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def serial_screw_torque(q, qdd):
    """Lagrange by hand: the nut's COG c(q) = o + pitch q u + R_A Rot(z, q) com, u = R_A z.
    Its velocity (pitch u + u x (c - o - pitch q u)) qd and its angular velocity u qd
    make the kinetic energy 1/2 M qd^2 with M = m |dc/dq|^2 + z . I z, constant (u x r
    keeps its length as r turns about u); the potential is -m g . c(q). So
    tau = M qdd - m g . dc/dq."""
    r_a, z = _rpy(AXIS_RPY), np.array([0.0, 0.0, 1.0])
    u = r_a @ z
    inertia = np.array([[INERTIA[0], INERTIA[3], INERTIA[4]],
                        [INERTIA[3], INERTIA[1], INERTIA[5]],
                        [INERTIA[4], INERTIA[5], INERTIA[2]]])
    r = r_a @ _rotation(z, q) @ np.array(COM)
    dc = PITCH * u + np.cross(u, r)
    mass_matrix = MASS * dc @ dc + z @ inertia @ z
    return mass_matrix * qdd - MASS * np.array([0.0, 0.0, -GRAVITY]) @ dc


# --- the tests ------------------------------------------------------------------------------

def test_the_built_in_kinds_are_registered_by_their_type_names():
    assert joints.names() == ('revolute', 'prismatic', 'spherical', 'universal', 'fixed')
    assert joints.kind('continuous') is None
    assert joints.kind('continuous', aliases=True) is joints.Revolute
    assert joints.kind('screw') is None


def test_a_registered_kind_loads_and_solves_in_the_tree(helical):
    mech = cog_id_ros.Mechanism.from_parameters(serial_screw())
    assert joints.kind('helical') is Helical
    assert mech.joint_types == ['helical'] and mech.coordinate_types == ['helical']
    assert mech.joint_specs[0].kind.pitch == PITCH and mech.dof == 1
    q, qd, qdd = motion(0.3)
    expected = np.array([serial_screw_torque(a, b) for a, b in zip(q, qdd)])
    for backend in BACKENDS:
        solver = cog_id_ros.InverseDynamics(mech, backend=backend)
        tau = solver.torques(q[:, None], qd[:, None], qdd[:, None])[:, 0]
        np.testing.assert_allclose(tau, expected, rtol=1e-10, atol=1e-12)
        one = solver.sample_torques([q[2]], [qd[2]], [qdd[2]])
        assert one[0] == pytest.approx(expected[2], rel=1e-10)


def test_a_registered_kind_closes_a_loop(helical):
    """Screw jack: the thread turns the motor's angle theta into the nut's travel
    d = -pitch theta, so T = 1/2 (I_screw + m_nut pitch^2) thetadot^2 and V = m_nut g d:
    tau = (I_screw + m_nut pitch^2) thetaddot - m_nut g pitch."""
    mech = cog_id_ros.Mechanism.from_parameters(screw_jack())
    assert [lp.name for lp in mech.model.loops] == ['thread'] and mech.dof == 1
    q, qd, qdd = motion(0.3)
    expected = (SCREW_INERTIA + NUT_MASS * PITCH ** 2) * qdd - NUT_MASS * GRAVITY * PITCH
    for backend in BACKENDS:
        solver = cog_id_ros.InverseDynamics(mech, backend=backend)
        tau = solver.torques(q[:, None], qd[:, None], qdd[:, None])[:, 0]
        np.testing.assert_allclose(tau, expected, rtol=1e-10, atol=1e-12)
        positions = solver.solve_positions(q[:, None])
        guide, thread = mech.joints.index('guide'), mech.joints.index('thread')
        np.testing.assert_allclose(positions[:, guide], -PITCH * q, atol=1e-12)
        np.testing.assert_allclose(positions[:, thread], -q, atol=1e-12)


def test_a_registered_kind_reads_and_refuses_its_parameters(helical):
    p = serial_screw()
    del p['joints.thread.pitch']
    with pytest.raises(MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(p)
    assert info.value.parameter == 'joints.thread.pitch'
    p = serial_screw()
    p['joints.thread.axis2'] = [1.0, 0.0, 0.0]
    with pytest.raises(MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(p)
    assert 'a helical joint has one axis' in str(info.value)
    p = serial_screw()
    p['joints.thread.lead'] = 0.1
    with pytest.raises(MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(p)
    assert str(info.value).endswith('effort, pitch)')


def test_tools_show_a_registered_kind_as_it_says(helical):
    mech = cog_id_ros.Mechanism.from_parameters(serial_screw())
    (row,) = inspect_pose.joint_rows(mech)
    assert row[1] == 'helical' and row[5] == 'rad'
    assert mech.active_kinds[0].effort_unit == 'N m' and not mech.active_kinds[0].wraps
    assert mechanism_plot.figure_kind(mech, mech.assembled_coordinates) == 'spatial'


def test_without_registration_the_type_is_refused_naming_the_kinds():
    with pytest.raises(MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(serial_screw())
    assert info.value.parameter == 'joints.thread.type'
    assert 'must be one of revolute, prismatic, spherical, universal, fixed' in str(info.value)


# --- where kind names are spelled -----------------------------------------------------------

#: the kinds' names, and the spellings the core used for them before they had a class
KIND_NAMES = {'revolute', 'prismatic', 'spherical', 'universal', 'fixed', 'continuous',
              'ball', 'quaternion'}
#: the modules that may spell them: the kinds, and the URDF reader (URDF's type names)
MAY_SPELL = 3


def modules_spelling_kind_names():
    """Modules of the package with a string literal that is a kind's name (docstrings and
    words inside messages are not literals of a name)."""
    spelling = []
    for path in sorted(PACKAGE.rglob('*.py')):
        tree = ast.parse(path.read_text(), str(path))
        if any(isinstance(node, ast.Constant) and node.value in KIND_NAMES
               for node in ast.walk(tree)):
            spelling.append(str(path.relative_to(PACKAGE)))
    return spelling


def test_kind_names_are_spelled_in_few_modules():
    spelling = modules_spelling_kind_names()
    assert 'core/kinematics/joints.py' in spelling
    assert len(spelling) <= MAY_SPELL, spelling


def test_the_page_shows_the_class_the_test_registers():
    """docs/adding_a_joint_kind.md walks through this very Helical, word for word."""
    import inspect as source
    page = (PACKAGE.parent / 'docs' / 'adding_a_joint_kind.md').read_text()
    assert source.getsource(Helical) in page
