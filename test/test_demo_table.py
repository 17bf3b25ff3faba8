"""``./dev table`` (cog_id_ros.demos.table): the torques it prints, and no ``-0.0000``."""
import os
import re
import shutil
import sys

import numpy as np
import pytest

from cog_id_ros.demos import paper_four_bar, table

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


# --- Reliability 2, adversarial check: where the demos find their config files -----------------

#: the checkout's config/ (the fixture below moves paper_four_bar's idea of it)
CHECKOUT_CONFIG = paper_four_bar.SOURCE_CONFIG


def demo_config(directory):
    """``directory`` made to hold the demos' config files (copies of the checkout's)."""
    directory.mkdir(parents=True, exist_ok=True)
    for name in ('paper_four_bar_a.yaml', 'paper_four_bar_b.yaml'):
        shutil.copy(os.path.join(CHECKOUT_CONFIG, name), directory / name)
    return directory


@pytest.fixture
def install_root(tmp_path, monkeypatch):
    """The package as if it were installed in ``tmp_path/root`` (the directory holding
    cog_id_ros/), run by an interpreter whose prefix is ``tmp_path/prefix``, with an ament
    prefix ``tmp_path/ament`` (indexing cog_id_ros) on AMENT_PREFIX_PATH. Nothing holds the
    config files yet."""
    root = tmp_path / 'root'
    monkeypatch.setattr(paper_four_bar, 'PACKAGE_DIR', str(root / 'cog_id_ros'), raising=False)
    monkeypatch.setattr(paper_four_bar, 'SOURCE_CONFIG', str(root / 'config'))
    monkeypatch.setattr(sys, 'prefix', str(tmp_path / 'prefix'))
    index = tmp_path / 'ament' / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'cog_id_ros').write_text('')
    (tmp_path / 'ament' / 'share' / 'cog_id_ros').mkdir()     # its share/, no config/ in it
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path / 'ament'))
    return tmp_path


def test_config_dir_looks_in_the_documented_order(install_root):
    """Reliability 2, adversarial check: installed with pip, the demos looked for their
    config files in <site-packages>/config (the source tree's place) and the ament index
    only, never where pip puts them. config_dir now takes the first of: the checkout's
    config/, share/cog_id_ros/config beside the package (pip --target), under sys.prefix
    (pip install), in the ament index; a directory without the files is passed over."""
    tmp = install_root
    places = [tmp / 'ament' / 'share' / 'cog_id_ros' / 'config',
              tmp / 'prefix' / 'share' / 'cog_id_ros' / 'config',
              tmp / 'root' / 'share' / 'cog_id_ros' / 'config',
              tmp / 'root' / 'config']

    def found():
        try:
            return paper_four_bar.config_dir()
        except paper_four_bar.ConfigNotFound:
            return None

    # the last place first: each one found takes over from the ones after it
    for k, place in enumerate(places):
        place.mkdir(parents=True)
        (place / 'paper_four_bar_a.yaml').write_text('')    # not both files: passed over
        assert found() == (str(places[k - 1]) if k else None)
        demo_config(place)
        assert found() == str(place)


def test_the_demos_say_in_one_line_where_they_looked(install_root, tmp_path, capsys):
    """Reliability 2, adversarial check: with the config files nowhere, cog_id_demo died with
    a traceback ("cannot read .../config/paper_four_bar_a.yaml", one place of several). The
    table and the Fig. 4 demo now exit 2 with one line naming every place looked in, in
    order; the Fig. 4 demo before starting anything."""
    from cog_id_ros.demos import fig4

    looked = [str(tmp_path / 'root' / 'config'),
              str(tmp_path / 'root' / 'share' / 'cog_id_ros' / 'config'),
              str(tmp_path / 'prefix' / 'share' / 'cog_id_ros' / 'config'),
              str(tmp_path / 'ament' / 'share' / 'cog_id_ros' / 'config')]
    expected = ("cannot find the demo's config files (paper_four_bar_a.yaml, "
                f"paper_four_bar_b.yaml): looked in {'; '.join(looked)}")
    assert table.main(['--step', '1']) == 2
    out = capsys.readouterr()
    assert out.out == ''
    assert out.err.endswith(f': {expected}\n') and out.err.count('\n') == 1, out.err
    assert fig4.main(['--output', str(tmp_path / 'fig4.png')]) == 2
    out = capsys.readouterr()
    assert (out.out, out.err) == ('', f'fig4: {expected}\n')
    assert not (tmp_path / 'fig4.png').exists()


def test_without_an_ament_index_the_line_says_so(install_root, monkeypatch, capsys):
    """Reliability 2, adversarial check: the ament index as the last place, when there is
    none to ask, is named with the reason."""
    monkeypatch.delenv('AMENT_PREFIX_PATH')
    assert table.main([]) == 2
    err = capsys.readouterr().err
    assert err.endswith("; the ament index (Environment variable 'AMENT_PREFIX_PATH' is not "
                        "set or empty)\n"), err
