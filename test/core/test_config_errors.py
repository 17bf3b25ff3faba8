"""Every configuration error of the mechanism parameter file (README) names its parameter."""
import pathlib

from mechanisms import double_pendulum, four_bar, from_yaml, with_changes
import pytest

import cog_id_ros

PAPER_A = 'config/paper_four_bar_a.yaml'


def pendulum_on_coupler(active):
    """Four-bar plus a pendulum hanging from the coupler: 2 DOF."""
    p = four_bar(active=active, init=[1.5707963267948966, -1.5707963267948966,
                                      1.5707963267948966, 1.5707963267948966, 0.0])
    p['mechanism.links'] = p['mechanism.links'] + ['bob']
    p['mechanism.joints'] = p['mechanism.joints'] + ['joint5']
    p.update({'links.bob.mass': 0.2, 'links.bob.com': [0.1, 0, 0],
              'joints.joint5.type': 'revolute', 'joints.joint5.parent': 'link2',
              'joints.joint5.child': 'bob', 'joints.joint5.parent_xyz': [0.25, 0, 0]})
    return p


CASES = [
    # (parameter, message fragment, changes to the paper four-bar (a))
    ('links.link2.mass', 'must be >= 0, got -1.0', {'links.link2.mass': -1.0}),
    ('links.link3.mass', 'missing', {'links.link3.mass': None}),
    ('links.link1.mass', 'must be a number', {'links.link1.mass': 'heavy'}),
    ('links.link1.inertia', 'positive semi-definite', {'links.link1.inertia': [1, 1, 1, 2, 0, 0]}),
    ('links.link1.inertia', 'triangle inequality', {'links.link1.inertia': [0.1, 0.1, 0.5, 0, 0, 0]}),
    ('links.link1.inertia', 'must have 6 entries', {'links.link1.inertia': [1.0, 2.0, 3.0]}),
    ('links.link1.inertia', 'must be symmetric', {'links.link1.inertia': [1, 0.1, 0, 0, 1, 0, 0, 0, 1]}),
    ('links.link1.com', 'must have 3 entries', {'links.link1.com': [0.25, 0.0]}),
    ('links.link1.mas', 'unknown parameter', {'links.link1.mas': 1.0}),
    ('links.link9.mass', "unknown link 'link9'", {'links.link9.mass': 1.0}),
    ('joints.joint2.axis', 'zero-length', {'joints.joint2.axis': [0, 0, 0]}),
    ('joints.joint2.type', "must be one of revolute, prismatic, spherical, universal, fixed, got 'ball'", {'joints.joint2.type': 'ball'}),
    ('joints.joint2.type', 'missing', {'joints.joint2.type': None}),
    ('joints.joint2.child', "unknown link 'lnk2'", {'joints.joint2.child': 'lnk2'}),
    ('joints.joint2.child', 'must differ from the parent', {'joints.joint2.child': 'link1'}),
    ('joints.joint2.parent_xyz', 'must have 3 entries', {'joints.joint2.parent_xyz': [0.5]}),
    ('joints.joint7.type', "unknown joint 'joint7'", {'joints.joint7.type': 'revolute'}),
    ('mechanism.links', "duplicate name 'link2'", {'mechanism.links': ['link1', 'link2', 'link2']}),
    ('mechanism.joints', "duplicate name 'joint1'", {'mechanism.joints': ['joint1', 'joint1', 'joint3', 'joint4']}),
    ('mechanism.links', 'missing', {'mechanism.links': None}),
    ('mechanism.links', 'must not be listed', {'mechanism.links': ['ground', 'link1', 'link2', 'link3']}),
    ('mechanism.active_joints', "'joint9' is not in mechanism.joints", {'mechanism.active_joints': ['joint9']}),
    ('mechanism.initial_positions', 'must have 4 entries', {'mechanism.initial_positions': [0.0, 1.0]}),
    ('mechanism.torque_weights', 'must have 1 entries', {'mechanism.torque_weights': [1.0, 2.0]}),
    ('mechanism.torque_weights', 'must be positive', {'mechanism.torque_weights': [0.0]}),
    ('mechanism.gravity', 'must have 3 entries', {'mechanism.gravity': [0.0, -9.81]}),
    ('mechanism.gravty', 'unknown parameter', {'mechanism.gravty': [0.0, -9.81, 0.0]}),
    ('mechanism.initial_positions', 'cannot be closed',
     {'joints.joint3.parent_xyz': [2.5, 0.0, 0.0]}),
    ('mechanism.links', "link 'link4' is not connected",
     {'mechanism.links': ['link1', 'link2', 'link3', 'link4'], 'links.link4.mass': 1.0}),
]


@pytest.mark.parametrize('parameter,fragment,changes', CASES, ids=[c[0] + ':' + c[1][:20] for c in CASES])
def test_configuration_error_names_the_parameter(parameter, fragment, changes):
    params = with_changes(from_yaml(PAPER_A), **{k.replace('.', '__'): v for k, v in changes.items()})
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert info.value.parameter == parameter
    assert str(info.value).startswith(parameter + ': ')
    assert fragment in str(info.value)


def test_too_few_active_joints_for_the_degrees_of_freedom():
    params = with_changes(double_pendulum(), mechanism__active_joints=['shoulder'])
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert info.value.parameter == 'mechanism.active_joints'
    assert '1 active joint(s) for 2 degrees of freedom' in str(info.value)


def test_active_joints_that_leave_a_passive_joint_free_are_rejected():
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(pendulum_on_coupler(['joint1', 'joint3']))
    assert info.value.parameter == 'mechanism.active_joints'
    assert 'the motion is not determined' in str(info.value)
    assert 'joint5 can still move' in str(info.value)
    # the same mechanism with an actuator on the pendulum is fine
    assert cog_id_ros.Mechanism.from_parameters(pendulum_on_coupler(['joint1', 'joint5'])).dof == 2


def test_yaml_integers_are_accepted_where_floats_are_meant():
    params = with_changes(from_yaml(PAPER_A), joints__joint2__axis=[0, 0, 1], links__link1__mass=1,
                          mechanism__gravity=[0, -10, 0])
    assert cog_id_ros.Mechanism.from_parameters(params).dof == 1


def test_params_file_errors_name_the_file(tmp_path):
    with pytest.raises(cog_id_ros.MechanismConfigError, match='cannot read'):
        cog_id_ros.Mechanism.from_params_file(str(tmp_path / 'absent.yaml'))
    other = tmp_path / 'other_node.yaml'
    other.write_text('some_other_node:\n  ros__parameters:\n    x: 1\n')
    with pytest.raises(cog_id_ros.MechanismConfigError, match="no entry for node 'cog_id_node'"):
        cog_id_ros.Mechanism.from_params_file(str(other))


def test_node_entry_overrides_the_wildcard(tmp_path):
    text = pathlib.Path(PAPER_A).read_text(encoding='utf-8')
    path = tmp_path / 'both.yaml'
    path.write_text(text + '\ncog_id_node:\n  ros__parameters:\n    mechanism:\n      name: renamed\n')
    assert cog_id_ros.Mechanism.from_params_file(str(path)).name == 'renamed'
    assert cog_id_ros.Mechanism.from_params_file(str(path), node_name='other').name == 'paper_four_bar_a'


def test_assembly_holds_the_actuators_at_their_initial_positions():
    from mechanisms import four_bar
    # a rough guess of the passive joints: assembly closes the loop around joint1 = 0.8
    # (and says it moved them far)
    with pytest.warns(cog_id_ros.AssemblyWarning, match='moved passive joint'):
        mech = cog_id_ros.Mechanism.from_parameters(
            four_bar(ground=0.6, crank=0.2, coupler=0.6, rocker=0.4, active=('joint1',),
                     init=[0.8, -0.4, 1.5, 0.4]))
    assert mech.assembled_positions[0] == 0.8
    # rounded, slightly inconsistent redundant initial positions still assemble
    rounded = with_changes(from_yaml('config/paper_four_bar_b.yaml'),
                           mechanism__initial_positions=[1.5708, -1.5708, 1.5707, 1.5708])
    with pytest.warns(cog_id_ros.AssemblyWarning, match='within mechanism.setpoint_tolerance'):
        assert cog_id_ros.Mechanism.from_parameters(rounded).dof == 1


# --- Reliability item 4: whatever a file or dict holds, only MechanismConfigError, fast ------

LOAD_CHILD = r"""
import json, sys, time
import cog_id_ros
start = time.process_time()     # CPU seconds: the load of a shared machine does not count
try:
    cog_id_ros.Mechanism.from_params_file(sys.argv[1])
    out = {'type': None}
except BaseException as exc:  # noqa: BLE001 -- report whatever came out
    out = {'type': type(exc).__name__, 'parameter': getattr(exc, 'parameter', None),
           'message': str(exc)[:500]}
out['seconds'] = time.process_time() - start
print(json.dumps(out))
"""


def _paper_a_text():
    with open(PAPER_A, encoding='utf-8') as f:
        return f.read()


def _laughs(key, depth=11):
    """YAML lines of a 'billion laughs' list: 10**depth leaves from a few hundred bytes."""
    lines = f'      {key}: &{key}0 [a, a, a, a, a, a, a, a, a, a]\n'
    for i in range(1, depth):
        lines += f'      {key}{i}: &{key}{i} [' + ', '.join([f'*{key}{i - 1}'] * 10) + ']\n'
    return lines


def _laughs_map(depth=10):
    lines = '    junk0: &m0 {a: 1, b: 1, c: 1, d: 1, e: 1, f: 1, g: 1, h: 1, i: 1, j: 1}\n'
    for i in range(1, depth):
        lines += f'    junk{i}: &m{i} {{' + ', '.join(f'k{c}: *m{i - 1}' for c in range(10)) + '}\n'
    return lines


BAD_FILES = {
    # name: (text edit of paper_four_bar_a.yaml, parameter the error must name)
    'null mass': (lambda t: t.replace('        mass: 1.0\n', '        mass: ~\n', 1),
                  'links.link1.mass'),
    'null closure_tolerance': (
        lambda t: t.replace('      name: paper_four_bar_a\n',
                            '      name: paper_four_bar_a\n      closure_tolerance: ~\n'),
        'mechanism.closure_tolerance'),
    '400-digit integer': (lambda t: t.replace('        mass: 1.0\n', '        mass: ' + '9' * 400 + '\n', 1),
                          'links.link1.mass'),
    'recursive alias': (lambda t: t.replace('    links:\n', '    links: &l\n      loop: *l\n', 1),
                        'links.loop'),
    'billion laughs in a list': (
        lambda t: t.replace('      name: paper_four_bar_a\n', _laughs('n') + '      name: *n10\n'),
        'mechanism.name'),
    'billion laughs in mappings': (lambda t: t.replace('    links:\n', _laughs_map() + '    links:\n', 1),
                                   'params_file'),
    'nesting 5000 deep': (lambda t: t.replace('      gravity: [0.0, -9.81, 0.0]',
                                              '      gravity: ' + '[' * 5000 + ']' * 5000),
                          'params_file'),
}


def _run_load(path):
    import json
    import subprocess
    import sys
    try:
        done = subprocess.run([sys.executable, '-c', LOAD_CHILD, str(path)], capture_output=True,
                              text=True, timeout=30, cwd='.')
    except subprocess.TimeoutExpired:
        pytest.fail(f'loading {path} did not finish within 30 s')
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize('case', sorted(BAD_FILES))
def test_bad_file_values_are_config_errors_within_two_seconds(case, tmp_path):
    """Reliability item 4: nulls, a 400-digit integer, recursive and exponential ("billion
    laughs") YAML aliases, absurd nesting: MechanismConfigError naming the parameter (or
    params_file) within 2 s of CPU time (wall time on a loaded machine is not the loader's),
    never TypeError, OverflowError, RecursionError or a hang (30 s of wall time)."""
    edit, parameter = BAD_FILES[case]
    text = edit(_paper_a_text())
    assert text != _paper_a_text()
    path = tmp_path / 'bad.yaml'
    path.write_text(text, encoding='utf-8')
    out = _run_load(path)
    assert out['type'] == 'MechanismConfigError', out
    if parameter is not None:
        assert out['parameter'] == parameter, out
    assert out['message'].startswith(out['parameter'] + ': ')
    assert out['seconds'] < 2.0, out


def test_a_latin1_file_is_a_config_error_naming_the_file(tmp_path):
    """Reliability item 4: a file that is not UTF-8 is MechanismConfigError on params_file
    that says to save it as UTF-8, not UnicodeDecodeError."""
    path = tmp_path / 'latin1.yaml'
    path.write_bytes(_paper_a_text().replace('name: paper_four_bar_a', 'name: m\u00e9canisme')
                     .encode('latin-1'))
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_params_file(str(path))
    assert info.value.parameter == 'params_file'
    assert 'UTF-8' in str(info.value)


def _recursive_dict():
    d = {}
    d['x'] = d
    return d


def _nested(depth):
    d = {'mass': 1.0}
    for _ in range(depth):
        d = {'a': d}
    return d


ODD_DICTS = {
    'None mass': {'links.link1.mass': None},
    'None closure_tolerance': {'mechanism.closure_tolerance': None},
    'huge int mass': {'links.link1.mass': 10 ** 400},
    'huge int in a vector': {'links.link1.com': [10 ** 400, 0, 0]},
    'huge int gravity': {'mechanism.gravity': [0, -(10 ** 309), 0]},
    'recursive dict': {'links': _recursive_dict()},
    'deeply nested dict': {'links': {'link1': _nested(5000)}},
    'non-string key': {7: 1.0},
    'tuple key': {('links', 'link1'): 1.0},
    'set as names': {'mechanism.active_joints': {'joint3'}},
    'bytes as vector': {'links.link1.com': b'abc'},
}


@pytest.mark.parametrize('case', sorted(ODD_DICTS))
def test_from_parameters_raises_only_config_errors(case):
    """Reliability item 4: Mechanism.from_parameters with None, huge integers, nested or
    recursive dicts and non-string keys raises MechanismConfigError only."""
    params = dict(from_yaml(PAPER_A))
    changes = ODD_DICTS[case]
    for key, value in changes.items():
        if isinstance(key, str) and isinstance(value, dict) and key in ('links',):
            params = {k: v for k, v in params.items() if not k.startswith('links.link1.')}
        params[key] = value
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert str(info.value).startswith(info.value.parameter + ': ')
    assert len(str(info.value)) < 1000


# --- Reliability item 2: a rigid (0 DOF) mechanism is refused at load ---------------------

def test_a_rigid_mechanism_is_refused_at_load():
    """Reliability item 2: paper four-bar (a) with joint2 made prismatic has 0 degrees of
    freedom; it must not load (its first trajectory used to crash in numpy)."""
    params = with_changes(from_yaml(PAPER_A), joints__joint2__type='prismatic')
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert info.value.parameter == 'mechanism.joints'
    message = str(info.value)
    assert 'rigid' in message and '0 degrees of freedom' in message
    assert 'prismatic where revolute was meant' in message


# --- Reliability item 5 (load part): documented bounds on every value -----------------------

BOUNDS = [
    # (parameter, value just beyond the documented bound, bound as printed)
    ('links.link1.mass', 1e300, '1e+09'),
    ('links.link1.mass', 2e9, '1e+09'),
    ('links.link2.com', [1e308, 0.0, 0.0], '1e+06'),
    ('links.link3.inertia', [1e13, 1e13, 1e13, 0, 0, 0], '1e+12'),
    ('joints.joint2.parent_xyz', [2e6, 0.0, 0.0], '1e+06'),
    ('joints.joint4.child_xyz', [0.0, -1e300, 0.0], '1e+06'),
    ('joints.joint2.parent_rpy', [0.0, 0.0, 1e300], '1e+06'),
    ('mechanism.gravity', [0.0, -1e300, 0.0], '10000'),
    ('mechanism.gravity', [8000.0, -8000.0, 0.0], '10000'),
    ('mechanism.initial_positions', [1.5707963267948966, -1.5707963267948966, 1e300, 1.5707963267948966], '1e+06'),
    ('mechanism.closure_tolerance', 1e300, '0.001'),
    ('mechanism.max_condition_number', 1e300, '1e+15'),
    ('mechanism.max_condition_number', 0.5, '1'),
]


@pytest.mark.parametrize('parameter,value,bound', BOUNDS, ids=[f'{p}={v}' for p, v, _ in BOUNDS])
def test_values_beyond_the_documented_bounds_are_refused(parameter, value, bound):
    """Reliability item 5: masses, lengths, inertias, gravity, angles and tolerances near
    1e308 (that made every torque infinite) are refused at load, naming the bound."""
    params = with_changes(from_yaml(PAPER_A), **{parameter.replace('.', '__'): value})
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert info.value.parameter == parameter
    assert bound in str(info.value)


def test_a_huge_axis_is_normalised_not_zeroed():
    """Reliability item 5: an axis of entries near 1e308 overflowed its norm to inf and
    became a zero axis silently; it is the same axis as [0, 0, 1]."""
    big = with_changes(from_yaml(PAPER_A), joints__joint2__axis=[0.0, 0.0, 1e308])
    mech = cog_id_ros.Mechanism.from_parameters(big)
    assert mech.joint_specs[1].kind.axis == (0.0, 0.0, 1.0)


def test_the_largest_values_within_the_bounds_give_finite_torques():
    """Reliability item 5: a mechanism at the documented bounds (masses 1e9 kg, inertia 1e12,
    |gravity| 1e4) driven by a moderate setpoint gives finite torques."""
    import numpy as np
    params = with_changes(from_yaml(PAPER_A), mechanism__gravity=[0.0, -1e4, 0.0])
    for link in ('link1', 'link2', 'link3'):
        params[f'links.{link}.mass'] = 1e9
        params[f'links.{link}.inertia'] = [1e12, 1e12, 1e12, 0, 0, 0]
    solver = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params))
    tau = solver.torques(np.array([[1.6]]), np.array([[100.0]]), np.array([[1e4]]))
    assert np.all(np.isfinite(tau))
    # and just beyond them the file is refused
    params['links.link1.mass'] = 1.01e9
    with pytest.raises(cog_id_ros.MechanismConfigError, match='links.link1.mass'):
        cog_id_ros.Mechanism.from_parameters(params)


# --- Issue 23 (was reliability item 21): any name of a link or joint ------------------------

def _renamed(params, old, new):
    def fix(v):
        if isinstance(v, str):
            return new if v == old else v
        if isinstance(v, list):
            return [fix(x) for x in v]
        return v
    return {k.replace(f'.{old}.', f'.{new}.'): fix(v) for k, v in params.items()}


ANY_NAMES = [
    ('link1', 'link.one'), ('joint2', 'joint.2'), ('link2', 'link-2'), ('joint3', 'joint 3'),
    ('link3', '3rd/left'), ('joint4', 'gelenk\u00e4'),
]


@pytest.mark.parametrize('old,new', ANY_NAMES, ids=[b[1] for b in ANY_NAMES])
def test_any_name_loads_and_outputs_carry_it(old, new):
    """Issue 23: names as CAD exporters write them ('.', '/', a leading digit, spaces,
    non-ASCII) load; ``links`` and ``joints`` carry them unchanged, and the torques are those
    of the same mechanism with its names as before."""
    params = _renamed(from_yaml(PAPER_A), old, new)
    mech = cog_id_ros.Mechanism.from_parameters(params)
    assert new in mech.links + mech.joints + mech.active_joints
    before = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(from_yaml(PAPER_A)))
    after = cog_id_ros.InverseDynamics(mech)
    q = before.mechanism.assembled_positions
    active = [q[j] for j in before.mechanism.active_index]
    assert after.sample_torques(active, [0.5] * len(active), [0.2] * len(active)) == \
        before.sample_torques(active, [0.5] * len(active), [0.2] * len(active))


def test_a_dotted_name_is_told_apart_in_unknown_parameters():
    params = _renamed(from_yaml(PAPER_A), 'link1', 'link.one')
    params['links.link.one.mas'] = 1.0
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert 'links.link.one.* takes' in str(info.value)


def test_a_name_with_a_control_character_is_refused():
    params = _renamed(from_yaml(PAPER_A), 'joint2', 'joint\n2')
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert info.value.parameter == 'mechanism.joints'
    assert "'joint\\n2'" in str(info.value) and 'U+000A' in str(info.value)


# --- Reliability item 24: what assembly had to change is said at load -------------------------

def test_a_missing_child_xyz_is_reported_with_the_joints_that_moved():
    """Reliability item 24: without joint4's child_xyz the loop only closes far from
    initial_positions; the load says so (assembly_warnings and an AssemblyWarning), with
    both values and the loop's joints to check."""
    from cog_id_ros.core.model.mechanism import AssemblyWarning
    params = with_changes(from_yaml(PAPER_A), joints__joint4__child_xyz=None)
    with pytest.warns(AssemblyWarning) as record:
        mech = cog_id_ros.Mechanism.from_parameters(params)
    assert len(mech.assembly_warnings) == 1
    note = mech.assembly_warnings[0]
    assert note in str(record[0].message)
    assert "'joint1' from 1.5708 to 1.0472" in note
    assert 'joints joint1, joint2, joint3, joint4' in note and 'geometry' in note
    # the well-formed file assembles where it is told to, without a note
    assert cog_id_ros.Mechanism.from_parameters(from_yaml(PAPER_A)).assembly_warnings == []


def test_an_actuator_the_assembly_had_to_move_is_refused():
    """Reliability item 24: the README says actuators are held at initial_positions; an
    actuator moved by more than setpoint_tolerance to close the loops is a
    MechanismConfigError on mechanism.initial_positions with both values and the loop."""
    from mechanisms import four_bar
    params = four_bar(ground=0.6, crank=0.2, coupler=0.6, rocker=0.4, active=('joint4',),
                      init=[1.0, -0.5, 2.0, 0.5])
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert info.value.parameter == 'mechanism.initial_positions'
    message = str(info.value)
    assert "active joint 'joint4' from 0.5 to 0.98" in message
    assert 'closure residual' in message and 'joints joint1, joint2, joint3, joint4' in message


def test_a_slightly_moved_redundant_actuator_is_noted():
    """Reliability item 24: rounded redundant initial positions still load, but the move of
    the actuators (within setpoint_tolerance) is noted with both values."""
    from cog_id_ros.core.model.mechanism import AssemblyWarning
    rounded = with_changes(from_yaml('config/paper_four_bar_b.yaml'),
                           mechanism__initial_positions=[1.5708, -1.5708, 1.5707, 1.5708])
    with pytest.warns(AssemblyWarning, match='within mechanism.setpoint_tolerance'):
        mech = cog_id_ros.Mechanism.from_parameters(rounded)
    assert any('from 1.5707 to' in note for note in mech.assembly_warnings)


def test_the_example_mechanisms_load_without_assembly_notes():
    """Reliability item 24 and 21: every config/*.yaml keeps valid names and assembles where
    its initial_positions say, without a note (guards the thresholds of the notes)."""
    import glob
    import warnings

    from cog_id_ros.core.model.mechanism import AssemblyWarning
    files = sorted(glob.glob('config/*.yaml'))
    assert len(files) >= 6
    with warnings.catch_warnings():
        warnings.simplefilter('error', AssemblyWarning)
        for path in files:
            assert cog_id_ros.Mechanism.from_params_file(path).assembly_warnings == []


@pytest.mark.parametrize('value', [10 ** 400, -(10 ** 309)], ids=['10**400', '-10**309'])
def test_numbers_too_large_for_a_float_say_so(value):
    """Reliability item 4: an integer (or numpy long double) beyond the float range is
    'too large for a float' on its parameter, not an OverflowError or a bare 'inf'."""
    import numpy as np
    for number in (value, np.longdouble(value)):
        params = with_changes(from_yaml(PAPER_A), links__link2__mass=number)
        with pytest.raises(cog_id_ros.MechanismConfigError) as info:
            cog_id_ros.Mechanism.from_parameters(params)
        assert info.value.parameter == 'links.link2.mass'
        assert 'too large for a float' in str(info.value)


@pytest.mark.parametrize('path', [0, True, None, 1.5, ['config/paper_four_bar_a.yaml']],
                         ids=['int', 'bool', 'None', 'float', 'list'])
def test_a_params_file_that_is_not_a_path_is_refused_without_touching_descriptors(path):
    """Reliability item 4 (found by the adversarial test): an int or True was taken as a
    file descriptor and closed (stdout itself for True); None raised TypeError."""
    import os
    with pytest.raises(cog_id_ros.MechanismConfigError, match='must be a path to a file'):
        cog_id_ros.Mechanism.from_params_file(path)
    os.fstat(1)                       # stdout is still open


def test_a_fifo_as_params_file_is_refused_instead_of_blocking(tmp_path):
    """Reliability item 4: reading a FIFO blocked for ever."""
    import os
    fifo = tmp_path / 'params.yaml'
    os.mkfifo(fifo)
    with pytest.raises(cog_id_ros.MechanismConfigError, match='not a regular file'):
        cog_id_ros.Mechanism.from_params_file(str(fifo))


def test_a_key_written_twice_is_an_error_not_the_last_one_winning(tmp_path):
    """Reliability item 4: 'mass: 1.0' then 'mass: -5.0' in one mapping silently took the
    second; a ROS parameter file with a repeated key is a mistake to point at."""
    text = pathlib.Path(PAPER_A).read_text(encoding='utf-8').replace(
        '        mass: 1.0\n', '        mass: 1.0\n        mass: 2.0\n', 1)
    path = tmp_path / 'dup.yaml'
    path.write_text(text, encoding='utf-8')
    with pytest.raises(cog_id_ros.MechanismConfigError, match="'mass' is written twice"):
        cog_id_ros.Mechanism.from_params_file(str(path))


def test_floats_without_a_dot_are_numbers_as_rcl_reads_them(tmp_path):
    """Reliability item 4: YAML 1.1 reads '1e0' as a string, so the API refused
    'mass: 1e0' as not a number while the node (rcl) reads 1.0."""
    text = pathlib.Path(PAPER_A).read_text(encoding='utf-8').replace('mass: 1.0', 'mass: 1e0')
    path = tmp_path / 'e.yaml'
    path.write_text(text, encoding='utf-8')
    assert cog_id_ros.Mechanism.from_params_file(str(path)).link_mass == [1.0, 1.0, 1.0]


def test_a_line_of_deeply_nested_block_entries_is_refused_before_parsing(tmp_path):
    """Reliability item 4: '- - - ... x' 50,000 deep crashes libyaml's parser."""
    path = tmp_path / 'deep.yaml'
    path.write_text('- ' * 50000 + 'x\n', encoding='utf-8')
    with pytest.raises(cog_id_ros.MechanismConfigError, match='block entries'):
        cog_id_ros.Mechanism.from_params_file(str(path))


def test_a_tiny_axis_is_a_direction_like_any_other():
    """docs/mechanism.md: any finite non-zero axis is normalised ([1e-200, 0, 0] was refused
    as zero-length)."""
    params = with_changes(from_yaml(PAPER_A), joints__joint2__axis=[0.0, 0.0, 1e-200])
    mech = cog_id_ros.Mechanism.from_parameters(params)
    assert mech.joint_specs[1].kind.axis == (0.0, 0.0, 1.0)


@pytest.mark.parametrize('name', ['mechanism__gravity', 'mechanism__closure_tolerance',
                                  'links__link1__com'])
def test_an_empty_mapping_is_not_silently_the_default(name):
    """Reliability item 4 (found by the adversarial test): 'gravity: {}' meant 'use the
    default' without a word."""
    params = with_changes(from_yaml(PAPER_A), **{name: {}})
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(params)
    assert info.value.parameter == name.replace('__', '.')


def test_a_closure_tolerance_no_double_can_meet_is_refused():
    """5e-324 was accepted: no pose would ever count as closed."""
    params = with_changes(from_yaml(PAPER_A), mechanism__closure_tolerance=5e-324)
    with pytest.raises(cog_id_ros.MechanismConfigError, match='at least 1e-14'):
        cog_id_ros.Mechanism.from_parameters(params)


def test_a_dotted_name_keying_a_mapping_is_written_flat(tmp_path):
    """Issue 23: rcl files the keys after a mapping whose key holds '.' under a wrong name
    (links: {"link.one": {...}, link2: ...} gives links.link.link2.*; checked with rcl,
    Jazzy), so a parameter file with one is refused naming the key and the escape, flat
    quoted keys, which load; a dotted name as the last part of a key is fine."""
    from cog_id_ros.description.params_file import load_params_file
    base = ('/**:\n  ros__parameters:\n    mechanism:\n      initial_positions: {"a.b": 1.0, c: 2.0}\n'
            '    links:\n')
    nested = tmp_path / 'nested.yaml'
    nested.write_text(base + '      "link.one": {mass: 1.0}\n      link2: {mass: 2.0}\n')
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        load_params_file(str(nested))
    assert info.value.parameter == 'links.link.one'
    assert "'links.link.link2'" in str(info.value) and '"link.one.mass"' in str(info.value)
    flat = tmp_path / 'flat.yaml'
    flat.write_text(base + '      "link.one.mass": 1.0\n      link2: {mass: 2.0}\n')
    params = load_params_file(str(flat))
    assert params['links.link.one.mass'] == 1.0 and params['links.link2.mass'] == 2.0
    assert params['mechanism.initial_positions.a.b'] == 1.0
    last = tmp_path / 'last.yaml'       # nothing follows it: rcl reads it right
    last.write_text(base + '      link2: {mass: 2.0}\n      "link.one": {mass: 1.0}\n')
    assert load_params_file(str(last))['links.link.one.mass'] == 1.0
