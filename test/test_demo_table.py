"""``./dev table`` (cog_id_ros.demos.table): the torques it prints, and no ``-0.0000``."""
import re

import numpy as np
import pytest

from cog_id_ros.demos import table

#: a printed number that is zero with a minus sign: -0, -0.0, -0.0000, -0.00e+00
NEGATIVE_ZERO = re.compile(r'(?<![\w.])-0(?:\.0*)?(?:e[+-]?\d+)?(?![\w.])')


def test_negative_zero_pattern():
    assert NEGATIVE_ZERO.findall('a -0.0000 b -0.00e+00 c -0 |') == ['-0.0000', '-0.00e+00', '-0']
    assert not NEGATIVE_ZERO.search('0.0000 -0.0001 -1.0725 10.0000 -20.0 x-0.5')


@pytest.mark.parametrize('step', [0.1, 0.05, 0.01])
def test_table_prints_the_torques_and_no_negative_zero(capsys, step):
    """Reliability 2, item 17: ./dev table printed -0.0000 where a torque is a few 1e-16
    below zero (t = 1 s, where the motion turns). Every number printed is the torque rounded
    to four decimals, and none is a zero with a minus sign."""
    assert table.main(['--step', str(step)]) == 0
    out = capsys.readouterr().out
    assert not NEGATIVE_ZERO.search(out), NEGATIVE_ZERO.findall(out)
    t = np.arange(0.0, table.DURATION + 1e-9, step)
    tau_a, tau_b = table.paper_torques(t)
    rows = [line.split() for line in out.splitlines() if re.match(r'\s*\d+\.\d\d\s', line)]
    assert len(rows) == len(t)
    for row, time, a, (b1, b3) in zip(rows, t, tau_a, tau_b):
        printed = [float(row[k]) for k in (0, 3, 5, 6)]
        np.testing.assert_allclose(printed, [time, a, b1, b3], rtol=0, atol=5.0001e-5)


def test_fixed_point_keeps_every_sign_but_that_of_zero():
    assert table.fixed(-1e-16, 8) == '  0.0000'
    assert table.fixed(-0.0, 8) == '  0.0000'
    assert table.fixed(-0.00004, 8) == '  0.0000'
    assert table.fixed(-0.00006, 8) == ' -0.0001'
    assert table.fixed(-3.37974, 8) == ' -3.3797'
    assert table.fixed(1.5, 6, 2) == '  1.50'
