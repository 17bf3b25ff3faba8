"""Reliability 2, items 9 and 10: what the URDF reader (cog_id_ros.description.urdf) and the
parameter-file reader (cog_id_ros.description.params_file) say about values, numbers, text
and sizes they cannot take (docs/urdf.md, "Errors" and "The parser").

Every load here runs with warnings turned into errors: a value out of bounds must be named
at the URDF element it was written in before any arithmetic on it, never after a numpy
RuntimeWarning.
"""
import os
import warnings

import pytest
from test_urdf import CONFIG, four_bar_urdf, four_bar_urdf_params, inertial
import yaml

from cog_id_ros import Mechanism, MechanismConfigError
from cog_id_ros.description.params_file import MAX_FILE_CHARS, load_params_file, read_document
from cog_id_ros.description.urdf import native_parameters
from cog_id_ros.description.urdf_xml import MAX_URDF_SIZE


def refused(params, base_dir=None):
    """The MechanismConfigError of loading ``params``; any warning on the way fails."""
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        with pytest.raises(MechanismConfigError) as info:
            Mechanism.from_parameters(params, base_dir)
    return info.value


def with_robot(urdf, tip=False):
    params = four_bar_urdf_params(tip)
    params['robot_description'] = urdf
    return params


def line_of(text, fragment):
    assert text.count(fragment) == 1, fragment
    return text[:text.index(fragment)].count('\n') + 1


def heavy_tip(**inertia):
    """The four-bar whose coupler carries a 1 kg link welded to it by the fixed joint
    tip_mount (so merged into the coupler)."""
    return four_bar_urdf(tip=True).replace(
        '<link name="coupler_tip"/>',
        '<link name="coupler_tip">' + inertial(1.0, '0.01 0 0', '0 0 0', **inertia) + '</link>')


# --- item 9: the URDF reader ------------------------------------------------------------------

def test_a_fixed_joint_origin_out_of_bounds_is_named_at_its_element_without_warnings():
    """Reliability 2, item 9: a fixed-joint origin of 1e200 printed four numpy
    RuntimeWarnings while the welded links were merged, then named links.coupler.com (got
    4.5e+199), a parameter the user never wrote. It is refused at the joint's <origin>, with
    its line and the value as written, before any arithmetic."""
    urdf = heavy_tip().replace('xyz="0.35 0 0"', 'xyz="1e200 0 0"')
    err = refused(with_robot(urdf, tip=True))
    assert err.parameter == 'robot_description'
    assert str(err) == (
        f"robot_description: line {line_of(urdf, 'tip_mount')}: xyz='1e200 0 0' in <origin> "
        f"of joint 'tip_mount': entries must lie within +-1e+06 m, got 1e200")


COUPLER = '<link name="coupler"><inertial>'
ROCKER_ORIGIN = '<origin xyz="0.4 0 0" rpy="0 0 0"/>'
COUPLER_AXIS = '<origin xyz="0.1 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-6"'


@pytest.mark.parametrize('old,new,line_at,message', [
    (ROCKER_ORIGIN, '<origin xyz="4e6 0 0" rpy="0 0 0"/>', 'rocker_joint',
     "xyz='4e6 0 0' in <origin> of joint 'rocker_joint': entries must lie within +-1e+06 m, "
     "got 4e6"),
    (ROCKER_ORIGIN, '<origin xyz="0.4 0 0" rpy="0 -2e6 0"/>', 'rocker_joint',
     "rpy='0 -2e6 0' in <origin> of joint 'rocker_joint': entries must lie within +-1e+06 "
     "rad, got -2e6"),
    ('xyz="0.175 0.0 0.01"', 'xyz="0.175 1.5e6 0.01"', COUPLER,
     "xyz='0.175 1.5e6 0.01' in <origin> of <inertial> of link 'coupler': entries must lie "
     "within +-1e+06 m, got 1.5e6"),
    ('xyz="0.175 0.0 0.01" rpy="0 0 0"', 'xyz="0.175 0.0 0.01" rpy="0 0 3e6"', COUPLER,
     "rpy='0 0 3e6' in <origin> of <inertial> of link 'coupler': entries must lie within "
     "+-1e+06 rad, got 3e6"),
    ('<mass value="1.2"/>', '<mass value="2e9"/>', COUPLER,
     "value='2e9' in <mass> of link 'coupler': must be at most 1e+09 kg, got 2e9"),
    ('ixx="0.0002"', 'ixx="1e308"', COUPLER,
     "ixx='1e308' in <inertia> of link 'coupler': must lie within +-1e+12 kg m^2, got 1e308"),
    ('ixx="0.0002"', 'ixx="1e400"', COUPLER,
     "ixx='1e400' in <inertia> of link 'coupler': must lie within +-1e+12 kg m^2, got 1e400"),
    (COUPLER_AXIS, COUPLER_AXIS.replace('0 0 1', '0 0 1e309'), 'coupler_joint',
     "xyz='0 0 1e309' in <axis> of joint 'coupler_joint': is too large for a double, got 1e309"),
    (COUPLER_AXIS, COUPLER_AXIS.replace('-6', '-1e999'), 'coupler_joint',
     "lower='-1e999' in <limit> of joint 'coupler_joint': is too large for a double, got "
     "-1e999"),
], ids=['joint_xyz', 'joint_rpy', 'com', 'inertial_rpy', 'mass', 'inertia', 'inertia_inf',
        'axis_inf', 'limit_inf'])
def test_every_value_of_the_urdf_is_bounded_at_its_element(old, new, line_at, message):
    """Reliability 2, item 9: values of the URDF beyond the native schema's bounds were
    named by native parameters (joints.rocker_joint.parent_xyz, links.coupler.com), an
    inertia of 1e308 said "got inf" after a RuntimeWarning, an inertial rpy of 3e6 was
    taken, and numbers beyond a double said only "must be a number". Each is refused at its
    element with its line, the bound and the value as written."""
    urdf = four_bar_urdf()
    assert urdf.count(old) == 1
    urdf = urdf.replace(old, new)
    err = refused(with_robot(urdf))
    assert err.parameter == 'robot_description'
    assert str(err) == f'robot_description: line {line_of(urdf, line_at)}: {message}'


@pytest.mark.parametrize('inertia,problem', [
    ({'ixx': 1.0, 'iyy': 0.1, 'izz': 0.1}, 'violates the triangle inequality'),
    ({'ixx': 0.1, 'iyy': 0.1, 'izz': 0.1, 'ixy': 0.5}, 'must be positive semi-definite'),
], ids=['triangle', 'not_psd'])
def test_a_bad_inertia_of_a_welded_link_is_named_at_its_own_element(inertia, problem):
    """Reliability 2, item 9: an inertia that no body can have, on a link welded to the
    coupler by a fixed joint, was reported as links.coupler.inertia: the merged body, not
    the URDF line at fault. It is refused at the welded link's own <inertia>, and so is one
    of a link on its own (which the core named links.<link>.inertia)."""
    urdf = heavy_tip(**inertia)
    err = refused(with_robot(urdf, tip=True))
    assert err.parameter == 'robot_description'
    line = line_of(urdf, '<link name="coupler_tip">')
    assert str(err).startswith(
        f"robot_description: line {line}: <inertia> of link 'coupler_tip': {problem}")
    urdf = four_bar_urdf().replace('ixx="0.0002"', 'ixx="0.5"')
    err = refused(with_robot(urdf))
    assert str(err).startswith(f'robot_description: line {line_of(urdf, COUPLER)}: <inertia> '
                               f"of link 'coupler': violates the triangle inequality")


@pytest.mark.parametrize('written', [
    '1_0', '\u0661', '\uff11', '1\u00a00', 'inf', 'nan', 'Infinity', '0x10', '1e', '.',
    '+-1', '1,5', '\u22121'])
def test_urdf_numbers_are_read_as_strictly_as_urdfdom(written):
    """Reliability 2, item 9: xyz="0 0 1_0" read as 10.0 and Arabic-Indic (or full-width)
    digits as theirs, where docs/urdf.md claims urdfdom's strictness (std::stringstream in
    the classic locale: ASCII digits, sign, point, exponent). Each is refused naming the
    element, the attribute, its line and the text; the spellings urdfdom takes read as
    before."""
    urdf = four_bar_urdf().replace(ROCKER_ORIGIN, f'<origin xyz="0.4 0 {written}"/>')
    err = refused(with_robot(urdf))
    assert err.parameter == 'robot_description'
    assert str(err) == (
        f"robot_description: line {line_of(urdf, 'rocker_joint')}: xyz={'0.4 0 ' + written!r} "
        f"in <origin> of joint 'rocker_joint': {written!r} is not a number; write numbers as "
        f"urdfdom reads them: ASCII digits with an optional sign, decimal point and exponent "
        f"(e.g. -1.5e-3)")
    for text, value in (('1.', 1.0), ('.5', 0.5), ('+1', 1.0), ('-0', 0.0), ('1E-3', 1e-3),
                        ('007', 7.0), ('2.5e+0', 2.5), ('1e-400', 0.0)):
        urdf = four_bar_urdf().replace(ROCKER_ORIGIN,
                                       f'<origin xyz=" 0.4&#9;0\n{text} " rpy="0 0 0"/>')
        native = native_parameters(with_robot(urdf))
        assert native['joints.rocker_joint.parent_xyz'] == [0.4, 0.0, value]


def test_a_lone_surrogate_in_robot_description_is_named_with_its_line():
    """Reliability 2, item 9: a lone surrogate ('\\ud800', e.g. from a JSON escape) in the
    robot_description given to Mechanism.from_parameters raised UnicodeEncodeError from
    expat. It is a MechanismConfigError naming robot_description, its line and column."""
    urdf = four_bar_urdf().replace('<link name="rocker">', '<link name="rock\ud800er">')
    err = refused(with_robot(urdf))
    assert err.parameter == 'robot_description'
    line = line_of(urdf, 'rock\ud800')
    assert str(err) == (f'robot_description: line {line}: not well-formed XML '
                        f'(column 17): U+D800 is a lone surrogate, not a character; remove it '
                        f'or write the character it stands for')


def test_a_urdf_file_that_is_not_utf8_says_so(tmp_path):
    """Reliability 2, item 9: a mechanism.urdf_file with a Latin-1 byte (an accented link
    name saved in the wrong encoding) was refused as "not well-formed (invalid token)",
    which does not say what to fix. The message names the byte and UTF-8; a file that
    declares its encoding is read as such."""
    urdf = four_bar_urdf().replace('"rocker"', '"rock\u00e9r"')
    (tmp_path / 'latin1.urdf').write_bytes(urdf.encode('latin-1'))
    params = with_robot(None)
    del params['robot_description']
    params['mechanism']['urdf_file'] = 'latin1.urdf'
    err = refused(params, str(tmp_path))
    assert err.parameter == 'mechanism.urdf_file'
    line = line_of(urdf, '<link name="rock')
    assert str(err) == (
        f"mechanism.urdf_file: {tmp_path / 'latin1.urdf'} line {line}: "
        f"not well-formed XML (column 17): not well-formed (invalid token) (byte 0xe9 is not "
        f"UTF-8: save the file as UTF-8, or declare its encoding in <?xml version=\"1.0\" "
        f"encoding=\"...\"?>)")
    (tmp_path / 'latin1.urdf').write_bytes(
        b'<?xml version="1.0" encoding="ISO-8859-1"?>\n' + urdf.encode('latin-1'))
    err = refused(params, str(tmp_path))      # read: the closure names the link as it was
    assert str(err).endswith("unknown link 'rocker' (not a link of the URDF: ground, crank, "
                             "coupler, rock\u00e9r)")


@pytest.mark.parametrize('name', ['robot\x00.urdf', 'robot\ud800.urdf'])
def test_a_urdf_file_name_no_file_can_have_is_named(tmp_path, name):
    """Reliability 2, item 9: a mechanism.urdf_file holding a NUL or a lone surrogate raised
    ValueError or UnicodeEncodeError from os.stat. It is a MechanismConfigError on
    mechanism.urdf_file."""
    params = four_bar_urdf_params()
    del params['robot_description']
    params['mechanism']['urdf_file'] = name
    err = refused(params, str(tmp_path))
    assert err.parameter == 'mechanism.urdf_file'
    assert 'not a possible file name' in str(err)
    str(err).encode('utf-8')          # printable: the name is quoted with escapes


def test_loop_closure_offsets_on_a_welded_link_are_bounded_as_written():
    """Reliability 2, item 9: a loop closure attached to a link welded to another was
    re-expressed before the core checked it: a child_rpy of 1e300 became an angle within
    +-pi (taken, the load then failing on mechanism.initial_positions), a child_xyz of 1e200
    was named joints.closing_joint.child_xyz, got 4.4e+199. Both are refused as written."""
    for key, value, unit in (('child_rpy', 1e300, 'rad'), ('child_xyz', 1e200, 'm')):
        params = four_bar_urdf_params(tip=True)
        params['loop_closures']['closing_joint'][key] = [0.0, 0.0, value]
        err = refused(params)
        assert err.parameter == f'loop_closures.closing_joint.{key}'
        assert str(err).endswith(f'entries must lie within +-1e+06 {unit}, got {value!r} at '
                                 f'index 2')


def test_numbers_in_a_parameter_file_are_read_as_rcl_reads_them(tmp_path):
    """Reliability 2, item 9, in the parameter file: YAML 1.1 read mass: 1_0 as 10, 1:30 as
    90 (base 60) and 0b1 as 1, where rcl's parser (strtoll, then strtod, each taking the whole
    text) reads the strings '1_0', '1:30' and '0b1', which the node refuses as no number.
    The API now refuses them alike, naming the parameter; and it reads as doubles what rcl
    does and YAML 1.1 does not (-.5, .5e1)."""
    with open(os.path.join(CONFIG, 'paper_four_bar_a.yaml'), encoding='utf-8') as stream:
        text = stream.read()
    assert text.count('mass: 1.0') == 3
    path = tmp_path / 'four_bar.yaml'
    for written in ('1_0', '1_0.5', '1:30', '1:30.5', '0b1'):
        path.write_text(text.replace('mass: 1.0', f'mass: {written}', 1), encoding='utf-8')
        assert load_params_file(str(path))['links.link1.mass'] == written
        assert read_document(str(path), duplicate_keys=True)['/**']['ros__parameters'][
            'links']['link1']['mass'] == written
        with pytest.raises(MechanismConfigError) as info:
            Mechanism.from_params_file(str(path))
        assert info.value.parameter == 'links.link1.mass'
        assert str(info.value) == f'links.link1.mass: must be a number, got {written!r}'
    for written, value in (('-.5', -0.5), ('.5e1', 5.0), ('1e0', 1.0), ('010', 8), ('1', 1)):
        path.write_text(text.replace('mass: 1.0', f'mass: {written}', 1), encoding='utf-8')
        assert load_params_file(str(path))['links.link1.mass'] == value


# --- item 10: one size limit for a URDF -------------------------------------------------------

def params_file_with(urdf, path, extra=''):
    """A parameter file of the four-bar with ``urdf`` as its robot_description, written as a
    YAML block scalar (indented, as a URDF is pasted into a file)."""
    params = four_bar_urdf_params()
    del params['robot_description']
    rest = yaml.safe_dump(params, default_flow_style=None, width=1000)
    text = ('/**:\n  ros__parameters:\n    robot_description: |-\n'
            + ''.join(f'      {line}\n' for line in urdf.split('\n'))
            + ''.join(f'    {line}\n' for line in rest.splitlines()) + extra)
    path.write_text(text, encoding='utf-8')
    return str(path)


def padded(size):
    """The four-bar URDF padded to ``size`` characters with <visual> elements (skipped by
    the reader), as a URDF with meshes is."""
    urdf = four_bar_urdf()
    visual = ('<visual><geometry><mesh filename="meshes/ground_part_{:06d}.stl"/></geometry>'
              '</visual>')
    parts, k = [], 0
    room = size - len(urdf) - len('<link name="ground"></link>') + len('<link name="ground"/>')
    while room > 0:
        item = visual.format(k) + '\n'
        if len(item) > room:
            item = ' ' * (room - 1) + '\n'
        parts.append(item)
        room -= len(item)
        k += 1
    urdf = urdf.replace('<link name="ground"/>',
                        '<link name="ground">\n' + ''.join(parts)[:-1] + '</link>')
    assert len(urdf) == size
    return urdf


def test_a_parameter_file_takes_a_robot_description_up_to_the_urdf_limit(tmp_path):
    """Reliability 2, item 10: the parameter file's cap (512 kB) also capped the
    robot_description in it, while the URDF reader takes 8 MB. A file with a 1 MB URDF
    loads (in Mechanism.from_params_file and in the node's check of its files); the rest of
    the file keeps its own cap."""
    path = params_file_with(padded(1024 * 1024), tmp_path / 'big_urdf.yaml')
    assert os.path.getsize(path) > 2 * MAX_FILE_CHARS
    mech = Mechanism.from_params_file(path)
    assert mech.joints == ['crank_joint', 'coupler_joint', 'rocker_joint', 'closing_joint']
    assert mech.dof == 1
    assert 'robot_description' in read_document(path, duplicate_keys=True)['/**'][
        'ros__parameters']
    comment = '# ' + 'x' * MAX_FILE_CHARS + '\n'
    path = params_file_with(padded(1024 * 1024), tmp_path / 'too_much_else.yaml', comment)
    with pytest.raises(MechanismConfigError) as info:
        load_params_file(path)
    assert info.value.parameter == 'params_file'
    assert f'larger than the supported {MAX_FILE_CHARS // 1024} kB' in str(info.value)
    assert 'robot_description' in str(info.value)


def test_a_robot_description_beyond_the_urdf_limit_is_refused_naming_it(tmp_path):
    """Reliability 2, item 10: a parameter file whose robot_description exceeds the URDF
    reader's limit is refused on robot_description with that limit (not as a parameter
    file too large)."""
    path = params_file_with(padded(MAX_URDF_SIZE + 1), tmp_path / 'huge_urdf.yaml')
    with pytest.raises(MechanismConfigError) as info:
        Mechanism.from_params_file(path)
    assert info.value.parameter == 'robot_description'
    assert str(info.value) == (f'robot_description: is {MAX_URDF_SIZE + 1} characters long, '
                               f'more than the supported 8 MB')


# --- Reliability 2, adversarial checks: <limit> ------------------------------------------------

#: the coupler joint's axis and <limit> (revolute) as four_bar_urdf writes them
COUPLER_LIMIT = ('<origin xyz="0.1 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>'
                 '<limit lower="-6" upper="6" effort="0" velocity="1.0"/>')
CRANK_AXIS = ('type="continuous"><parent link="ground"/><child link="crank"/>'
              '<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>')


def coupler_limit(**attributes):
    """The four-bar with the coupler joint's <limit> attributes replaced."""
    urdf = four_bar_urdf()
    assert urdf.count(COUPLER_LIMIT) == 1
    limit = '<limit ' + ' '.join(f'{k}="{v}"' for k, v in attributes.items()) + '/>'
    return urdf.replace(COUPLER_LIMIT, COUPLER_LIMIT[:COUPLER_LIMIT.index('<limit')] + limit)


def crank_limit(limit):
    """The four-bar with ``limit`` on its continuous crank joint."""
    urdf = four_bar_urdf()
    assert urdf.count(CRANK_AXIS) == 1
    return urdf.replace(CRANK_AXIS, CRANK_AXIS + limit)


def not_a_number(attribute, text, joint):
    return (f'{attribute}={text!r} in <limit> of joint {joint!r}: {text!r} is not a number; '
            f'write numbers as urdfdom reads them: ASCII digits with an optional sign, '
            f'decimal point and exponent (e.g. -1.5e-3)')


@pytest.mark.parametrize('urdf,line_at,message', [
    (coupler_limit(lower=-6, upper=6, effort=0, velocity='abc'), 'coupler_joint',
     not_a_number('velocity', 'abc', 'coupler_joint')),
    (coupler_limit(lower=-6, upper=6, effort=0, velocity='nan'), 'coupler_joint',
     not_a_number('velocity', 'nan', 'coupler_joint')),
    (coupler_limit(lower=-6, upper=6, effort=0, velocity='1_0'), 'coupler_joint',
     not_a_number('velocity', '1_0', 'coupler_joint')),
    (coupler_limit(lower=-6, upper=6, effort=0, velocity='1e400'), 'coupler_joint',
     "velocity='1e400' in <limit> of joint 'coupler_joint': is too large for a double, got "
     "1e400"),
    (crank_limit('<limit lower="x" upper="y" effort="1" velocity="1"/>'), 'crank_joint',
     not_a_number('lower', 'x', 'crank_joint')),
    (crank_limit('<limit lower="-1" upper="y" effort="1" velocity="1"/>'), 'crank_joint',
     not_a_number('upper', 'y', 'crank_joint')),
    (crank_limit('<limit effort="inf" velocity="1"/>'), 'crank_joint',
     not_a_number('effort', 'inf', 'crank_joint')),
    (four_bar_urdf(tip=True).replace(
        '<origin xyz="0.35 0 0" rpy="0.3 -0.2 1.1"/>',
        '<origin xyz="0.35 0 0" rpy="0.3 -0.2 1.1"/>'
        '<limit lower="0" upper="0" effort="0" velocity="\u0661"/>'), 'tip_mount',
     not_a_number('velocity', '\u0661', 'tip_mount')),
], ids=['velocity_abc', 'velocity_nan', 'velocity_1_0', 'velocity_1e400',
        'continuous_lower', 'continuous_upper', 'continuous_effort', 'fixed_velocity'])
def test_every_number_of_a_limit_is_read_as_urdfdom_reads_it(urdf, line_at, message):
    """Reliability 2, adversarial check: the reader took <limit velocity="abc">, "nan" and
    "1_0", and lower="x" upper="y" on a continuous joint, all of which urdfdom refuses
    (it parses lower, upper, effort and velocity of a joint's <limit> whatever the joint's
    type). Each is refused with the element, the attribute, its line and the text, as the
    reader's other numbers are; what a joint does not use is still not used."""
    err = refused(with_robot(urdf, tip='tip_mount' in urdf))
    assert err.parameter == 'robot_description'
    assert str(err) == f'robot_description: line {line_of(urdf, line_at)}: {message}'


def test_limit_numbers_a_joint_does_not_use_are_checked_and_ignored():
    """Reliability 2, adversarial check, the other side: well-written numbers of a <limit>
    that the joint does not use (position limits of a continuous joint, any limit of a fixed
    joint, the velocity of any) are read and then ignored, as before."""
    urdf = crank_limit('<limit lower="-1" upper="-2" effort="3.5" velocity="-7"/>')
    native = native_parameters(with_robot(urdf))
    assert 'joints.crank_joint.lower' not in native
    assert 'joints.crank_joint.upper' not in native
    assert native['joints.crank_joint.effort'] == 3.5
    urdf = four_bar_urdf(tip=True).replace(
        '<origin xyz="0.35 0 0" rpy="0.3 -0.2 1.1"/>',
        '<origin xyz="0.35 0 0" rpy="0.3 -0.2 1.1"/>'
        '<limit lower="1" upper="-1" effort="5" velocity="+.5e1"/>')
    native = native_parameters(with_robot(urdf, tip=True))
    assert not any(key.startswith('joints.tip_mount.') for key in native)
    native = native_parameters(with_robot(coupler_limit(lower=-6, upper=6, effort=0,
                                                        velocity='2E+3')))
    assert native['joints.coupler_joint.lower'] == -6.0
    assert native['joints.coupler_joint.upper'] == 6.0
    assert 'joints.coupler_joint.effort' not in native
