"""The replay demo (``./dev replay``) and cog_id_simulate on the paper's four-bar against an
independent engine: the closed form tau = (5/3) m L^2 thetaddot + 2 m g L cos(theta)
integrated by a plain RK4 here, with the same held torques.
"""
import math
import os

import numpy as np
import pytest
from test_exit_statuses import dev_help_entry, numbers, paragraph, read, returned_statuses

from cog_id_ros.demos import paper_four_bar, replay
from cog_id_ros.offline import cli, simulate
from cog_id_ros.offline import trajectory_io as tio

PARAMS_A = os.path.join(paper_four_bar.SOURCE_CONFIG, 'paper_four_bar_a.yaml')
TARGET = os.path.join(paper_four_bar.SOURCE_CONFIG, 'paper_four_bar_target.csv')


def closed_form_replay(t, tau, h, between):
    """theta at t[0] + k h of the parallelogram under the torques ``tau`` (rows at ``t``),
    held as cog_id_simulate holds them, by a plain RK4 of the closed form."""
    m, length, g = paper_four_bar.M, paper_four_bar.L, paper_four_bar.G
    inertia = 5.0 / 3.0 * m * length ** 2
    theta, omega = paper_four_bar.target_motion(t[:1])[:2]
    x = np.array([theta[0], omega[0]])
    out = [x[0]]
    for k in range(t.size - 1):
        held = tau[k] if between == 'hold' else 0.5 * (tau[k] + tau[k + 1])

        def f(y, held=held):
            return np.array([y[1], (held - 2 * m * g * length * math.cos(y[0])) / inertia])
        k1 = f(x)
        k2 = f(x + h / 2 * k1)
        k3 = f(x + h / 2 * k2)
        k4 = f(x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(x[0])
    return np.array(out)


@pytest.mark.parametrize('between, largest', [('hold', 4.05), ('linear', 1.98e-3)])
def test_the_replay_is_the_closed_form_integrated_independently(tmp_path, capsys, between,
                                                                largest):
    """Over the whole 2 s, with both ways between rows: the tool's motion is the closed
    form's to 1e-7 rad (the deviation from the target, 4.05 rad or 1.98e-3 rad, is the
    mechanism's, not the simulator's)."""
    assert cli.main(['--params-file', PARAMS_A, '--input', TARGET,
                     '--output', str(tmp_path / 'tau.csv')]) == 0
    assert simulate.main(['--params-file', PARAMS_A, '--input', str(tmp_path / 'tau.csv'),
                          '--initial-state', TARGET, '--between-rows', between,
                          '--output', str(tmp_path / 'm.csv')]) == 0
    capsys.readouterr()
    _, t, tau = tio.read_efforts(tmp_path / 'tau.csv')
    header, t_out, motion = tio.read_efforts(tmp_path / 'm.csv')
    theta = motion[:, header.index('joint3.position') - 1]
    expect = closed_form_replay(t, tau[:, 0], 0.001, between)
    np.testing.assert_allclose(theta, expect, rtol=0, atol=1e-7)
    error = np.abs(theta - paper_four_bar.target_motion(t_out)[0]).max()
    assert error == pytest.approx(largest, rel=0.01)


def test_the_bound_is_second_order_and_holds_at_every_time(tmp_path):
    assert replay.error_bound(0.0005) == pytest.approx(replay.error_bound(0.001) / 4, rel=1e-12)
    assert replay.GROWTH == pytest.approx(math.sqrt(6 * 9.81 / (5 * 0.5)))
    assert replay.main(['--output-dir', str(tmp_path)]) == 0
    t, theta = replay.crank_angle(tmp_path / 'replay_a_motion.csv')
    err = np.abs(theta - paper_four_bar.target_motion(t)[0])
    for k in range(20, t.size, 20):
        assert err[k] <= replay.error_bound(0.001, t[k]), t[k]
    assert (tmp_path / 'replay.png').read_bytes()[:4] == b'\x89PNG'


def test_beyond_the_bound_the_demo_fails_and_without_configs_it_does_not_run(
        tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(replay, 'error_bound', lambda h, duration=2.0: 1e-4)
    assert replay.main(['--output-dir', str(tmp_path)]) == replay.FAILED == 1
    assert 'NO' in capsys.readouterr().out

    def nowhere():
        raise paper_four_bar.ConfigNotFound("cannot find the demo's config files: looked in x")
    monkeypatch.setattr(replay, 'config_dir', nowhere)
    assert replay.main(['--output-dir', str(tmp_path)]) == replay.NOT_FOUND == 2
    assert 'looked in x' in capsys.readouterr().err


def test_every_status_of_dev_replay_is_written_where_it_is_described():
    statuses = returned_statuses(replay)
    assert statuses == {0, 1, 2}
    places = {
        'docs/cli.md': paragraph(read('docs/cli.md'), 'Exit status: 0 every replayed angle',
                                 '### The demo'),
        './dev help': dev_help_entry('replay'),
        'replay.py': paragraph(replay.__doc__, 'Exit status:'),
    }
    for place, text in places.items():
        assert statuses <= numbers(text), (place, statuses - numbers(text), text)
