"""The published robots whose loading takes tens of seconds, beside the others'
test_published_robots.py (the same checks, its helpers): the suite's two workers take one
file each, so these run beside the rest instead of after it."""
import pytest
from test_published_robots import (
    LARGE,
    REFUSED,
    SPIN,
    check_loads_with_locks,
    check_refused,
    check_refused_naming_locked_joints,
    check_torques,
    files,
    load,
    oracle,
    read,
    widened_talos,
)

LARGE_SPIN = [case for case in SPIN if case[0] in LARGE]
LARGE_REFUSED = [case for case in REFUSED if case[0] in LARGE]


@pytest.mark.parametrize('robot,spins', LARGE_SPIN)
def test_large_spinning_rods_are_refused_naming_locked_joints(robot, spins):
    check_refused_naming_locked_joints(robot, spins)


@pytest.mark.parametrize('robot,spins', LARGE_SPIN)
def test_large_spinning_robots_load_with_idle_spins_lock_or_the_named_joints(robot, spins):
    check_loads_with_locks(robot, spins)


@pytest.mark.parametrize('robot,parameter,fragment', LARGE_REFUSED)
def test_large_robots_refused_for_what_their_files_say(robot, parameter, fragment):
    check_refused(robot, parameter, fragment)


def test_the_old_digit_biped_gives_pinocchios_torques():
    pytest.importorskip('pinocchio')
    mech = load('old/digit_like_2legs', idle_spins='lock')
    check_torques(mech, oracle('old/digit_like_2legs', mech))


def test_talos_torques_match_pinocchio_with_its_shin_limits_widened(tmp_path):
    """TALOS as published: its two shin motors' URDF limits (those of the knee, [0, 2.618])
    leave no closed pose; it loads with a warning that every setpoint would be refused as
    'limit'. With those two <limit> widened (a copy), its 44 motors (12 of them coupled by
    <mimic>: redundant) give Pinocchio's torques."""
    pytest.importorskip('pinocchio')
    from pinocchio_loops import LoopOracle
    published = load('true_talos_2_legs', idle_spins='lock')
    shins = [text for text in published.assembly_warnings if 'outside its position limits'
             in text]
    assert len(shins) == 2 and "'leg_left_shin_joint'" in shins[0], shins
    mech, text = widened_talos(tmp_path)
    folder, _, loops = files('true_talos_2_legs')
    assert not [text for text in mech.assembly_warnings if 'position limits' in text]
    check_torques(mech, LoopOracle(text, read(folder, loops), held=mech.locked_joints), 2)
