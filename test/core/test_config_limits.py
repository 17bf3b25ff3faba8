"""Size limits of a mechanism (docs/mechanism.md): checked first, and loading below them
grows in proportion to the mechanism (reliability item 8)."""
import gc
import json
import subprocess
import sys
import time
import tracemalloc

import pytest
import yaml

import cog_id_ros
from cog_id_ros.core.kinematics.joints import Revolute
from cog_id_ros.core.kinematics.kinematics import BASE, JointSpec, KinematicModel
from cog_id_ros.core.model import mechanism as mechanism_module


def serial_chain(n, active=None):
    """A planar serial chain of n revolute joints (0.1 m rods), the first ``active`` (all by
    default) actuated."""
    active = n if active is None else active
    p = {'mechanism.name': 'chain', 'mechanism.gravity': [0.0, -9.81, 0.0],
         'mechanism.links': [f'l{i}' for i in range(n)],
         'mechanism.joints': [f'j{i}' for i in range(n)],
         'mechanism.active_joints': [f'j{i}' for i in range(active)]}
    for i in range(n):
        p[f'links.l{i}.mass'] = 1.0
        p[f'links.l{i}.com'] = [0.05, 0.0, 0.0]
        p[f'links.l{i}.inertia'] = [0.0, 1e-3, 1e-3, 0.0, 0.0, 0.0]
        p[f'joints.j{i}.type'] = 'revolute'
        p[f'joints.j{i}.parent'] = 'ground' if i == 0 else f'l{i - 1}'
        p[f'joints.j{i}.child'] = f'l{i}'
        if i:
            p[f'joints.j{i}.parent_xyz'] = [0.1, 0.0, 0.0]
    return p


def fan(k):
    """1 DOF with k loops: k parallelograms sharing the driven crank."""
    h = 1.5707963267948966
    p = {'mechanism.name': 'fan', 'links.crank.mass': 1.0, 'links.crank.com': [0.25, 0, 0],
         'joints.jc.type': 'revolute', 'joints.jc.parent': 'ground', 'joints.jc.child': 'crank'}
    links, joints, init = ['crank'], ['jc'], [h]
    for i in range(k):
        x = 0.5 * (i + 1)
        links += [f'r{i}', f'c{i}']
        p[f'links.r{i}.mass'] = p[f'links.c{i}.mass'] = 1.0
        for name, parent, child, pxyz, cxyz, q in (
                (f'g{i}', 'ground', f'r{i}', [x, 0, 0], None, h),
                (f'k{i}', 'crank', f'c{i}', [0.5, 0, 0], None, -h),
                (f'e{i}', f'c{i}', f'r{i}', [x, 0, 0], [0.5, 0, 0], h)):
            joints.append(name)
            init.append(q)
            p.update({f'joints.{name}.type': 'revolute', f'joints.{name}.parent': parent,
                      f'joints.{name}.child': child, f'joints.{name}.parent_xyz': pxyz})
            if cxyz:
                p[f'joints.{name}.child_xyz'] = cxyz
    p.update({'mechanism.links': links, 'mechanism.joints': joints,
              'mechanism.active_joints': ['jc'], 'mechanism.initial_positions': init})
    return p


def as_yaml(params):
    tree = {}
    for key, value in params.items():
        node = tree
        *path, last = key.split('.')
        for part in path:
            node = node.setdefault(part, {})
        node[last] = value
    return yaml.safe_dump({'/**': {'ros__parameters': tree}}, default_flow_style=None)


def refused(params):
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert str(info.value).startswith(info.value.parameter + ': ')
    return info.value


def test_a_chain_just_above_the_joint_limit_is_refused_naming_the_limit():
    """Reliability item 8: one joint more than MAX_JOINTS is a MechanismConfigError on
    mechanism.joints that names the count and the limit (the 300-joint chain of the issue
    took 9 s and 1.9 GB to build a solver)."""
    limit = mechanism_module.MAX_JOINTS
    params = serial_chain(limit + 1, active=1)
    error = refused(params)
    assert error.parameter == 'mechanism.joints'
    assert f'{limit + 1} joints, more than the supported {limit}' in str(error)


def test_links_just_above_the_limit_are_refused():
    """Reliability item 8: one link more than MAX_LINKS is refused on mechanism.links."""
    limit = mechanism_module.MAX_LINKS
    params = serial_chain(limit, active=1)
    params['mechanism.links'] = params['mechanism.links'] + ['extra']
    params['links.extra.mass'] = 1.0
    error = refused(params)
    assert error.parameter == 'mechanism.links'
    assert f'{limit + 1} links, more than the supported {limit}' in str(error)


def test_loops_just_above_the_limit_are_refused_before_assembly():
    """Reliability item 8: one loop more than MAX_LOOPS (the dense closure QR grows with
    the cube of the loop count) is refused on mechanism.joints."""
    limit = mechanism_module.MAX_LOOPS
    error = refused(fan(limit + 1))
    assert error.parameter == 'mechanism.joints'
    assert f'{limit + 1} closed loops, more than the supported {limit}' in str(error)


def test_active_joints_and_jacobian_columns_above_the_limits_are_refused():
    """Reliability item 8: more than MAX_ACTIVE_JOINTS actuators, or more than
    MAX_JACOBIAN_COLUMNS links x actuators (the size of the COG Jacobians the solver
    traces), are refused on mechanism.active_joints."""
    limit = mechanism_module.MAX_ACTIVE_JOINTS
    error = refused(serial_chain(limit + 1))
    assert error.parameter == 'mechanism.active_joints'
    assert f'{limit + 1} active joints, more than the supported {limit}' in str(error)
    columns = mechanism_module.MAX_JACOBIAN_COLUMNS
    n = int(columns ** 0.5) + 1                          # n x n just above the limit
    error = refused(serial_chain(n))
    assert error.parameter == 'mechanism.active_joints'
    assert f'{n * n} COG Jacobian columns, more than the supported {columns}' in str(error)


FAR_ABOVE = r"""
import json, sys, time
import cog_id_ros
start = time.perf_counter()
try:
    cog_id_ros.Mechanism.from_params_file(sys.argv[1])
    out = {'type': None}
except BaseException as exc:  # noqa: BLE001
    out = {'type': type(exc).__name__, 'parameter': getattr(exc, 'parameter', None),
           'message': str(exc)[:300]}
out['seconds'] = time.perf_counter() - start
print(json.dumps(out))
"""


@pytest.mark.parametrize('joints,parameter', [(1000, 'mechanism.joints'), (10000, 'params_file')])
def test_a_file_far_above_the_limits_is_refused_before_anything_is_built(tmp_path, joints,
                                                                          parameter):
    """Reliability item 8: a 10,000-joint file ended in MemoryError; it is refused before it
    is even parsed (larger than any mechanism within the limits), and a 1,000-joint file
    right after parsing, in a fraction of the time the old load took."""
    path = tmp_path / 'big.yaml'
    path.write_text(as_yaml(serial_chain(joints)), encoding='utf-8')
    try:
        done = subprocess.run([sys.executable, '-c', FAR_ABOVE, str(path)], capture_output=True,
                              text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f'loading a {joints}-joint file did not end within 60 s')
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out['type'] == 'MechanismConfigError', out
    assert out['parameter'] == parameter, out
    if parameter == 'mechanism.joints':
        assert f'{joints} joints, more than the supported' in out['message']
    else:
        assert 'larger than the supported' in out['message']


def _chain_specs(n):
    return [JointSpec(f'j{i}', Revolute((0.0, 0.0, 1.0)), BASE if i == 0 else i - 1, i,
                      (0.1, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            for i in range(n)]


def _tree_peak_memory(n):
    """Traced peak bytes of building the spanning tree of a serial chain of n links."""
    names, specs = [f'l{i}' for i in range(n)], _chain_specs(n)
    tracemalloc.start()
    KinematicModel(names, specs)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def _tree_seconds(sizes, rounds=7):
    """Best time of building the spanning tree of chains of each size, the sizes
    interleaved round by round (so that a busy spell of the machine hits them alike)."""
    cases = [([f'l{i}' for i in range(n)], _chain_specs(n)) for n in sizes]
    best = [float('inf')] * len(sizes)
    gc.collect()
    gc.disable()            # a collection in one run only would be noise
    try:
        for _ in range(rounds):
            for k, (names, specs) in enumerate(cases):
                start = time.perf_counter()
                KinematicModel(names, specs)
                best[k] = min(best[k], time.perf_counter() - start)
    finally:
        gc.enable()
    return best


def test_the_spanning_tree_is_built_in_linear_time_and_memory():
    """Reliability item 8: the breadth-first tree scanned every joint for every link and
    copied the whole path to every link (time and memory quadratic in the chain length:
    about x6 and x3.6 from 2,000 to 4,000 links). Doubling the chain now about doubles both."""
    m1, m2 = _tree_peak_memory(2000), _tree_peak_memory(4000)
    assert m2 / m1 < 2.6, (m1, m2)
    t1, t2 = _tree_seconds([2000, 4000])
    assert t2 / t1 < 3.5, (t1, t2)     # quadratic: about 4 to 6
