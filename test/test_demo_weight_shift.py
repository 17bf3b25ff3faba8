"""The floating-base example (cog_id_ros.demos.weight_shift): a published biped sways from
one foot to the other with both feet kept still on the ground."""
import numpy as np

from cog_id_ros.demos import weight_shift


def test_the_sway_keeps_the_feet_still_and_moves_the_load(tmp_path, capsys):
    assert weight_shift.main(['--output', str(tmp_path / 'sway.png'), '--samples', '21']) == 0
    assert (tmp_path / 'sway.png').stat().st_size > 10_000
    assert '-0.0 ' not in capsys.readouterr().out
    t, pose, theta, out, mech = weight_shift.weight_shift(samples=9)
    solver = weight_shift.InverseDynamics(mech)
    feet0 = weight_shift.foot_poses(solver, theta[0])
    for k in range(len(t)):          # the feet stay where they were, in the world
        feet = weight_shift.foot_poses(solver, theta[k])
        for name in weight_shift.CONTACTS:
            shift = np.array([0.0, pose[k, 1], 0.0])
            np.testing.assert_allclose(feet[name][0] + shift, feet0[name][0], atol=1e-9)
            np.testing.assert_allclose(feet[name][1], feet0[name][1], atol=1e-9)
    right, left = (out.wrenches[name][:, 2] for name in weight_shift.CONTACTS)
    # over the left foot (pelvis at +y) the left foot carries nearly all of it, and back
    assert left[2] > 0.9 * (left[2] + right[2]) and right[6] > 0.9 * (left[6] + right[6])
    assert np.abs(out.base_wrench).max() < 1e-9
