"""Writes the closed-loop URDF test models of test/models/ (kept as files, in the form such
models are published: robot.urdf and the loop list robot.yaml beside it).

    python test/models/make_models.py test/models

Each model is drawn at its URDF pose (every joint at 0) from the world frame of every link,
so that the loops close there by construction; the joint origins and axes are computed
from those frames and written with 12 significant digits.
"""
import math
import os
import sys

import numpy as np


def rpy_matrix(rpy):
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def rpy_of(R):
    yaw = math.atan2(R[1, 0], R[0, 0])
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    roll = math.atan2(R[2, 1], R[2, 2])
    return roll, pitch, yaw


def fmt(v):
    return ' '.join(f'{round(float(x), 12) + 0.0:.12g}' for x in v)


class Model:
    def __init__(self, name, root):
        self.name = name
        self.frames = {root: (np.eye(3), np.zeros(3))}
        self.lines = ['<?xml version="1.0"?>', f'<robot name="{name}">', f'  <link name="{root}"/>']

    def link(self, name, rpy, pos, mass=None, com=(0, 0, 0), com_rpy=(0, 0, 0), inertia=None):
        self.frames[name] = (rpy_matrix(rpy), np.array(pos, float))
        if mass is None:
            self.lines.append(f'  <link name="{name}"/>')
            return
        ixx, iyy, izz, ixy, ixz, iyz = inertia
        self.lines += [f'  <link name="{name}">', '    <inertial>',
                       f'      <origin xyz="{fmt(com)}" rpy="{fmt(com_rpy)}"/>',
                       f'      <mass value="{mass}"/>',
                       f'      <inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" izz="{izz}"/>',
                       '    </inertial>', '  </link>']

    def joint(self, name, kind, parent, child, axis_world=None, limit='lower="-3.0" upper="3.0" effort="20.0" velocity="10.0"'):
        Rp, pp = self.frames[parent]
        Rc, pc = self.frames[child]
        R = Rp.T @ Rc
        xyz = Rp.T @ (pc - pp)
        out = [f'  <joint name="{name}" type="{kind}">', f'    <parent link="{parent}"/>',
               f'    <child link="{child}"/>', f'    <origin xyz="{fmt(xyz)}" rpy="{fmt(rpy_of(R))}"/>']
        if kind != 'fixed':
            axis = Rc.T @ np.array(axis_world, float)
            out.append(f'    <axis xyz="{fmt(axis)}"/>')
            out.append(f'    <limit {limit}/>')
        out.append('  </joint>')
        self.lines += out

    def text(self):
        return '\n'.join(self.lines + ['</robot>', ''])


I1 = (0.0021, 0.0034, 0.0027, 0.0002, -0.0001, 0.00015)
I2 = (0.0011, 0.0016, 0.0013, -0.0001, 0.00005, 0.0001)
Y = (0.0, 1.0, 0.0)


def five_bar():
    m = Model('five_bar_robot', 'base_link')
    A1, B1, P, B2, A2 = ((-0.1, 0.03, 0.0), (-0.19, 0.05, -0.12), (0.0, 0.04, -0.3),
                         (0.2, 0.025, -0.1), (0.1, 0.03, 0.0))
    m.link('1/proximal', (0.1, -0.9, 0.2), A1, 0.4, (0.04, 0.01, -0.03), (0.2, 0.1, -0.3), I1)
    m.link('1/distal', (-0.2, 0.6, 0.1), B1, 0.3, (0.05, -0.01, 0.08), (0.0, 0.3, 0.1), I2)
    m.link('1/tip', (0.0, 0.0, 0.0), P)
    m.link('2/proximal', (0.0, 0.5, 0.0), A2, 0.4, (0.03, 0.0, -0.05), (0.1, 0.0, 0.2), I1)
    m.link('2/distal', (0.3, -0.4, -0.1), B2, 0.3, (-0.06, 0.01, -0.07), (0.2, -0.1, 0.0), I2)
    m.link('2/tip', (0.4, 0.2, 0.3), P)
    m.joint('motor/1', 'revolute', 'base_link', '1/proximal', Y)
    m.joint('elbow/1', 'revolute', '1/proximal', '1/distal', Y)
    m.joint('1/tip_joint', 'fixed', '1/distal', '1/tip')
    m.joint('motor/2', 'revolute', 'base_link', '2/proximal', Y)
    m.joint('elbow/2', 'revolute', '2/proximal', '2/distal', Y)
    m.joint('2/tip_joint', 'fixed', '2/distal', '2/tip')
    loops = ("closed_loop: [['1/tip', '2/tip_joint']]\ntype: ['3d']\n"
             "name_mot: ['motor/1', 'motor/2']\njoint_name: []\njoint_type: []\n")
    return m.text(), loops


def knee():
    m = Model('knee_four_bar', 'cuisse')
    A, B, D, C = (0.0, 0.0, 0.0), (0.03, 0.01, -0.04), (0.05, 0.0, 0.01), (0.09, 0.012, -0.03)
    M = tuple((np.array(B) + np.array(C)) / 2)
    m.link('manivelle', (0.2, 0.3, -0.1), A, 0.15, (0.015, 0.0, -0.02), (0.1, 0.2, 0.3), I2)
    m.link('bielle_haute', (-0.1, 0.2, 0.4), B, 0.08, (0.01, 0.002, 0.005), (0.0, 0.0, 0.5), I2)
    m.link('2nd_bar/lower', (0.3, -0.3, 0.0), C, 0.07, (-0.01, 0.0, -0.004), (0.2, 0.1, 0.0), I2)
    m.link('balancier_é', (0.0, 0.7, 0.2), D, 0.12, (0.02, 0.0, -0.02), (0.0, 0.4, 0.0), I2)
    m.link('fermeture1_A', (0.3, -0.2, 0.5), M)
    m.link('fermeture1_B', (0.3, -0.2, 0.5), M)
    m.joint('moteur_genou', 'revolute', 'cuisse', 'manivelle', Y)
    m.joint('genou/2', 'revolute', 'manivelle', 'bielle_haute', Y)
    m.joint('fermeture1_A_joint', 'fixed', 'bielle_haute', 'fermeture1_A')
    m.joint('pivot_ä', 'revolute', 'cuisse', 'balancier_é', Y)
    m.joint('3rd', 'revolute', 'balancier_é', '2nd_bar/lower', Y)
    m.joint('fermeture1_B_joint', 'fixed', '2nd_bar/lower', 'fermeture1_B')
    loops = ("closed_loop: [['fermeture1_A', 'fermeture1_B']]\ntype: ['6D']\n"
             "name_mot: ['moteur_genou']\njoint_name: []\njoint_type: []\n")
    return m.text(), loops


def rsur(explicit=False):
    """Spatial crank-rocker: crank (R, motor) - ball (SPHERICAL edit) - coupler, welded (6d)
    to the end of a rocker (R) - cardan (UJOINT_XY edit); a counterweight on a hinge the file
    makes FIXED."""
    m = Model('rsur_robot', 'ground')
    A, B, D = (0.0, 0.0, 0.0), (0.08, 0.02, 0.01), (0.26, 0.16, 0.04)
    C = (0.25, 0.12, 0.19)
    m.link('crank', (0.2, -0.1, 0.3), A, 0.5, (0.03, 0.0, 0.01), (0.0, 0.2, 0.0), I1)
    m.link('counterweight', (0.0, 0.0, 0.4), (-0.03, 0.0, 0.0), 0.6, (-0.02, 0.0, 0.0), (0.0, 0.0, 0.0), I2)
    m.link('coupler', (0.1, 0.2, -0.3), B, 0.35, (0.08, 0.05, 0.09), (0.3, 0.0, 0.1), I1)
    m.link('weld_a', (0.0, 0.0, 0.0), C)
    m.link('rocker', (-0.3, 0.1, 0.2), D, 0.4, (0.0, -0.02, 0.07), (0.0, -0.2, 0.3), I1)
    if explicit:
        m.link('cardan_cross', (0.0, 0.0, 0.0), C)
    m.link('coupler_end', (0.0, 0.0, 0.0), C, 0.05, (-0.01, 0.0, 0.0), (0.0, 0.0, 0.0), I2)
    m.joint('crank_motor', 'revolute', 'ground', 'crank', (0.0, 0.0, 1.0))
    m.joint('cw_hinge', 'revolute', 'crank', 'counterweight', (0.0, 1.0, 0.0))
    m.joint('ball', 'revolute', 'crank', 'coupler', (0.0, 0.0, 1.0))
    m.joint('weld_a_mount', 'fixed', 'coupler', 'weld_a')
    m.joint('rocker_pivot', 'revolute', 'ground', 'rocker', (1.0, 0.0, 0.0))
    if explicit:
        m.joint('cardan_X', 'revolute', 'rocker', 'cardan_cross', (1.0, 0.0, 0.0))
        m.joint('cardan_Y', 'revolute', 'cardan_cross', 'coupler_end', (0.0, 1.0, 0.0))
        edits = "joint_name: ['ball', 'cw_hinge']\njoint_type: ['SPHERICAL', 'FIXED']\n"
    else:
        m.joint('cardan', 'revolute', 'rocker', 'coupler_end', (0.0, 0.0, 1.0))
        edits = ("joint_name: ['ball', 'cardan', 'cw_hinge']\n"
                 "joint_type: ['SPHERICAL', 'UJOINT_XY', 'FIXED']\n")
    loops = ("closed_loop: [['weld_a', 'coupler_end']]\ntype: ['6d']\n"
             "name_mot: ['crank_motor']\n" + edits)
    return m.text(), loops


def stewart_leg():
    """One leg of a Stewart-like platform: a crank (R, the motor) drives a slider (P) on the
    base through a rod with a ball joint at each end; the ball at the crank is written as
    three revolute joints through massless links (as URDFs write balls), the one at the
    slider is the loop list's '3d' pair. The rod spins freely about its own axis."""
    m = Model('stewart_leg', 'base')
    A, B, S = (0.0, 0.0, 0.1), (0.1, 0.0, 0.1), (0.14, 0.02, 0.35)
    m.link('crank', (0.0, 0.0, 0.3), A, 0.3, (0.05, 0.0, 0.0), (0.0, 0.0, 0.0), I1)
    m.link('ball_1/a', (0.0, 0.0, 0.0), B)
    m.link('ball_1/b', (0.0, 0.0, 0.0), B)
    d = np.array(S) - np.array(B)
    # the rod's frame: z along the rod
    z = d / np.linalg.norm(d)
    x = np.cross((0.0, 1.0, 0.0), z)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z])
    m.frames['rod'] = (R, np.array(B))
    m.lines += ['  <link name="rod">', '    <inertial>',
                f'      <origin xyz="{fmt(0.5 * np.linalg.norm(d) * np.array([0, 0, 1.0]) + np.array([0.004, -0.003, 0.0]))}" rpy="0.1 0.2 0.3"/>',
                '      <mass value="0.2"/>',
                f'      <inertia ixx="{I2[0]}" ixy="{I2[3]}" ixz="{I2[4]}" iyy="{I2[1]}" iyz="{I2[5]}" izz="{I2[2]}"/>',
                '    </inertial>', '  </link>']
    m.frames['rod_end'] = (R, np.array(S))
    m.lines.append('  <link name="rod_end"/>')
    m.link('slider', (0.0, 0.0, 0.0), S, 0.5, (0.0, 0.01, 0.02), (0.0, 0.0, 0.0), I1)
    m.joint('motor', 'revolute', 'base', 'crank', (0.0, 0.0, 1.0))
    m.joint('ball_1/x', 'revolute', 'crank', 'ball_1/a', tuple(R[:, 0]))
    m.joint('ball_1/y', 'revolute', 'ball_1/a', 'ball_1/b', tuple(R[:, 1]))
    m.joint('ball_1/z', 'revolute', 'ball_1/b', 'rod', tuple(R[:, 2]))
    m.joint('rod_end_joint', 'fixed', 'rod', 'rod_end')
    m.joint('slide', 'prismatic', 'base', 'slider', (0.0, 0.0, 1.0), 'lower="-1.0" upper="1.0" effort="100.0" velocity="1.0"')
    loops = ("closed_loop: [['rod_end', 'slider']]\ntype: ['3d']\nname_mot: ['motor']\n"
             "joint_name: []\njoint_type: []\n")
    return m.text(), loops


if __name__ == '__main__':
    out = sys.argv[1]
    for name, (urdf, loops) in {'five_bar': five_bar(), 'knee': knee(), 'rsur': rsur(),
                                'rsur_explicit': rsur(True), 'stewart_leg': stewart_leg()}.items():
        os.makedirs(os.path.join(out, name), exist_ok=True)
        with open(os.path.join(out, name, 'robot.urdf'), 'w') as f:
            f.write(urdf)
        with open(os.path.join(out, name, 'robot.yaml'), 'w') as f:
            f.write(loops)
