"""Spherical, universal and fixed joints: loop closures without a coordinate.

Each is checked against the same mechanism written with revolute joints through massless
helper links (the only way before), which must give the same torques: the helper links
carry no mass, so the two descriptions are one mechanism.
"""
import numpy as np
import pytest
from trajectories import TWINS, config_path, sample

import cog_id_ros
from cog_id_ros.params_file import load_params_file

BACKENDS = ('reference', 'python')


def rsur(params=None):
    return dict(params or load_params_file(config_path('spatial_rsur.yaml')))


def without(params, links=(), joints=()):
    """The params without the named links and joints (and their entries)."""
    out = {k: v for k, v in params.items()
           if not any(k.startswith(f'links.{n}.') for n in links)
           and not any(k.startswith(f'joints.{n}.') for n in joints)}
    out['mechanism.links'] = [n for n in params['mechanism.links'] if n not in links]
    out['mechanism.joints'] = [n for n in params['mechanism.joints'] if n not in joints]
    with_coordinate = [n for n in params['mechanism.joints']
                       if params[f'joints.{n}.type'] in ('revolute', 'prismatic')]
    out['mechanism.initial_positions'] = [
        x for n, x in zip(with_coordinate, params['mechanism.initial_positions'])
        if n not in joints]
    return out


def joint(params, name, kind, parent, child, **entries):
    params[f'joints.{name}.type'] = kind
    params[f'joints.{name}.parent'] = parent
    params[f'joints.{name}.child'] = child
    for key, value in entries.items():
        params[f'joints.{name}.{key}'] = value
    params['mechanism.joints'] = params['mechanism.joints'] + [name]


def rsur_universal():
    """spatial_rsur with its U joint (uni_a, uni_b through the massless uni_cross) as one
    universal joint between the coupler and the rocker."""
    p = without(rsur(), links=['uni_cross'], joints=['uni_a', 'uni_b'])
    joint(p, 'uni', 'universal', 'coupler', 'rocker', parent_xyz=[0.33, 0.0, 0.0],
          child_xyz=[0.12, 0.0, 0.0], axis=[0.0, 0.0, 1.0], axis2=[0.0, -1.0, 0.0])
    return p


def rsur_spherical():
    """spatial_rsur with its S joint (sph_z, sph_y, sph_x through sph_a, sph_b) as one
    spherical joint between the crank pin and the coupler."""
    p = without(rsur(), links=['sph_a', 'sph_b'], joints=['sph_z', 'sph_y', 'sph_x'])
    joint(p, 'sph', 'spherical', 'crank', 'coupler', parent_xyz=[0.05, 0.0, 0.0])
    return p


def torques(params, backend, q, qd, qdd, serial=False):
    solver = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params),
                                        backend=backend)
    if serial:
        return np.array([solver.torques(q[i], qd[i], qdd[i]) for i in range(len(q))])
    return solver.torques(q, qd, qdd)


@pytest.mark.parametrize('backend', BACKENDS)
@pytest.mark.parametrize('make', [rsur_universal, rsur_spherical])
def test_a_joint_without_coordinate_gives_the_torques_of_its_helper_links(make, backend):
    _, q, qd, qdd = sample('spatial_rsur.yaml', 120)
    expected = torques(rsur(), backend, q, qd, qdd)
    scale = np.abs(expected).max()
    assert np.abs(torques(make(), backend, q, qd, qdd) - expected).max() < 1e-12 * scale
    # sample by sample (warm-started Newton stops at the closure tolerance)
    assert np.abs(torques(make(), backend, q, qd, qdd, serial=True)
                  - expected).max() < 1e-8 * scale


@pytest.mark.parametrize('twin', sorted(TWINS))
def test_parallel_robots_with_spherical_joints_match_the_helper_link_ones(twin):
    original = TWINS[twin]
    _, q, qd, qdd = sample(original, 100)
    helper = cog_id_ros.Mechanism.from_params_file(config_path(original))
    native = cog_id_ros.Mechanism.from_params_file(config_path(twin))
    assert len(native.closure_joints) == 5 and native.dof == helper.dof
    assert len(native.joints) == len(helper.joints) - 15
    expected = cog_id_ros.InverseDynamics(helper, backend='python').torques(q, qd, qdd)
    for backend in BACKENDS:
        got = cog_id_ros.InverseDynamics(native, backend=backend).torques(q, qd, qdd)
        assert np.abs(got - expected).max() < 1e-12 * np.abs(expected).max(), backend
    # and so do the positions of the joints both have
    a = cog_id_ros.InverseDynamics(helper).solve_positions(q)[:, [helper.joints.index(j)
                                                                  for j in native.joints]]
    b = cog_id_ros.InverseDynamics(native).solve_positions(q)
    assert np.abs(a - b).max() < 1e-9


def test_a_fixed_joint_welds_two_links():
    """The rocker welded to a second, heavy link by a fixed joint: the torques are those of
    the rocker carrying that link's mass (the second link is also held by a revolute joint
    to the ground on the rocker's axis, so the fixed joint closes a loop)."""
    _, q, qd, qdd = sample('spatial_rsur.yaml', 60)
    base = rsur()
    # the rocker's axis in the ground frame: rocker_joint's attachment frame, axis -y
    rocker = {k.split('.')[-1]: v for k, v in base.items()
              if k.startswith('joints.rocker_joint.')}
    welded = dict(base)
    welded['mechanism.links'] = base['mechanism.links'] + ['weight']
    welded['links.weight.mass'] = 2.0
    welded['links.weight.com'] = [0.05, 0.01, 0.0]
    welded['links.weight.inertia'] = [1e-3, 2e-3, 2.5e-3, 1e-4, 0.0, 0.0]
    joint(welded, 'weight_hinge', 'revolute', 'ground', 'weight',
          parent_xyz=rocker['parent_xyz'], parent_rpy=rocker['parent_rpy'],
          axis=rocker['axis'])
    joint(welded, 'weld', 'fixed', 'rocker', 'weight')
    welded['mechanism.initial_positions'] = base['mechanism.initial_positions'] + [
        base['mechanism.initial_positions'][-1]]
    # the same weight as part of the rocker: mass and inertia combined (same frame)
    merged = dict(base)
    m1, c1 = base['links.rocker.mass'], np.array(base['links.rocker.com'])
    m2, c2 = 2.0, np.array([0.05, 0.01, 0.0])
    com = (m1 * c1 + m2 * c2) / (m1 + m2)

    def about(c, inertia, mass):
        ixx, iyy, izz, ixy, ixz, iyz = inertia
        i = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        d = c - com
        return i + mass * (d @ d * np.eye(3) - np.outer(d, d))
    total = about(c1, base['links.rocker.inertia'], m1) + about(
        c2, welded['links.weight.inertia'], m2)
    merged['links.rocker.mass'] = m1 + m2
    merged['links.rocker.com'] = com.tolist()
    merged['links.rocker.inertia'] = [total[0, 0], total[1, 1], total[2, 2], total[0, 1],
                                      total[0, 2], total[1, 2]]
    expected = torques(merged, 'python', q, qd, qdd)
    got = torques(welded, 'python', q, qd, qdd)
    assert np.abs(got - expected).max() < 1e-10 * np.abs(expected).max()
    assert np.abs(expected - torques(base, 'python', q, qd, qdd)).max() > 0.01 * np.abs(
        expected).max()        # the weight matters: the check above can fail


@pytest.mark.parametrize('change, parameter, words', [
    (lambda p: p.update({'mechanism.active_joints': ['uni']}), 'mechanism.active_joints',
     'universal joint'),
    (lambda p: p.pop('joints.uni.axis2'), 'joints.uni.axis2', 'missing'),
    (lambda p: p.update({'joints.uni.axis2': [0.0, 0.3, 1.0]}), 'joints.uni.axis2',
     'perpendicular'),
    (lambda p: p.update({'joints.uni.upper': 1.0}), 'joints.uni.upper', 'no coordinate'),
    (lambda p: p.update({'joints.rocker_joint.axis2': [1.0, 0.0, 0.0]}),
     'joints.rocker_joint.axis2', 'second axis of a universal joint'),
    (lambda p: p.update({'mechanism.initial_positions': [0.0] * 6}),
     'mechanism.initial_positions', 'spherical, universal or fixed'),
])
def test_errors_of_joints_without_coordinate_name_the_parameter(change, parameter, words):
    p = rsur_universal()
    change(p)
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(p)
    assert info.value.parameter == parameter and words in str(info.value), str(info.value)


def test_a_link_held_only_by_joints_without_coordinate_is_refused_with_the_reason():
    p = rsur_spherical()
    p = without(p, links=['uni_cross'], joints=['uni_a', 'uni_b'])
    joint(p, 'uni', 'universal', 'coupler', 'rocker', parent_xyz=[0.33, 0.0, 0.0],
          child_xyz=[0.12, 0.0, 0.0], axis=[0.0, 0.0, 1.0], axis2=[0.0, -1.0, 0.0])
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(p)
    text = str(info.value)
    assert "link 'coupler'" in text and 'sph, uni' in text and 'only close loops' in text


def test_position_and_effort_limits_of_the_native_schema():
    p = rsur()
    p['joints.crank_joint.lower'] = -1.0
    p['joints.crank_joint.upper'] = 2.0
    p['joints.crank_joint.effort'] = 5.0
    mech = cog_id_ros.Mechanism.from_parameters(p)
    assert mech.effort_limits == [5.0] and mech.active_position_limits == [(-1.0, 2.0)]
    solver = cog_id_ros.InverseDynamics(mech)
    solver.torques([1.9])
    for q in ([2.5], [-1.5]):
        with pytest.raises(cog_id_ros.SetpointError) as info:
            solver.sample_torques(q, [0.0], [0.0])
        assert info.value.reason == 'limit' and 'crank_joint' in str(info.value)
    batch = solver.evaluate(np.array([[0.5], [2.5], [0.6]]), on_invalid='skip')
    assert batch.valid.tolist() == [True, False, True]
    assert batch.errors[1].reason == 'limit'
    # the rates alone are checked without the positions (solver.cog_drifts, equation_of_motion)
    solver.equation_of_motion([0.5], [1.0])
    p['joints.crank_joint.upper'] = -2.0
    with pytest.raises(cog_id_ros.MechanismConfigError, match='joints.crank_joint.upper'):
        cog_id_ros.Mechanism.from_parameters(p)
    p['joints.crank_joint.upper'] = 2.0
    p['joints.crank_joint.effort'] = 0.0
    with pytest.raises(cog_id_ros.MechanismConfigError, match='joints.crank_joint.effort'):
        cog_id_ros.Mechanism.from_parameters(p)
