"""The names on the picture of ``cog_id_inspect --plot`` can be read (the issue "Reliability 2",
item 17): drawn over every marker, on a light box, beside their point, not over one another.

The picture is the one ``draw_mechanism`` saves (the figure is taken at ``savefig``), drawn
again on an Agg canvas to measure where its names are.
"""
import pathlib

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import Collection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
import numpy as np
import pytest

from cog_id_ros import Mechanism
from cog_id_ros.offline import mechanism_plot

CONFIG = pathlib.Path(__file__).resolve().parents[2] / 'config'


def saved_figure(monkeypatch, tmp_path, mech):
    """The Figure draw_mechanism saves for ``mech`` at its assembled pose."""
    saved = []
    savefig = Figure.savefig

    def keep(self, *args, **kwargs):
        saved.append(self)
        return savefig(self, *args, **kwargs)

    monkeypatch.setattr(Figure, 'savefig', keep)
    mechanism_plot.draw_mechanism(str(tmp_path / 'pose.png'), mech, mech.assembled_coordinates)
    assert len(saved) == 1
    return saved[0]


@pytest.mark.parametrize('config, names', [
    ('paper_four_bar_a.yaml', {'joint1', 'joint2', 'joint3', 'joint4', 'link1', 'link2',
                               'link3'}),
    # names close together: rocker1_joint beside rocker1's COG and coupler2's
    ('watt_six_bar.yaml', {'rocker1_joint', 'rocker1', 'coupler2', 'crank', 'crank_joint'}),
    # 3-D axes: mplot3d gives its collections their order by depth when drawn
    ('spatial_rsur.yaml', {'crank_joint', 'sph_z/sph_y/sph_x', 'crank', 'coupler', 'rocker'}),
])
def test_names_are_drawn_over_the_markers_and_clear_of_one_another(monkeypatch, tmp_path,
                                                                   config, names):
    """Reliability 2, item 17: joint markers (zorder 6-7) and COG dots (5) were drawn over the
    names (zorder 3), and names of nearby points over one another. Now every name is above
    every other artist of the axes, on a light box, beside its point, and no two boxes
    overlap."""
    fig = saved_figure(monkeypatch, tmp_path, Mechanism.from_params_file(CONFIG / config))
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    ax = fig.axes[0]
    labels = [t for t in ax.texts if t.get_text()]
    assert names <= {t.get_text() for t in labels}
    others = [a for a in ax.get_children() if isinstance(a, (Collection, Line2D, Patch))
              and a is not ax.patch and a.get_visible()]
    assert others
    top = max(a.get_zorder() for a in others)
    assert all(t.get_zorder() > top for t in labels), \
        sorted((t.get_zorder(), t.get_text()) for t in labels)[:3] + [('markers up to', top)]
    boxes = []
    for label in labels:
        patch = label.get_bbox_patch()
        assert patch is not None, label.get_text()
        assert patch.get_facecolor()[3] >= 0.5, label.get_text()      # a light box
        boxes.append(patch.get_window_extent(renderer))
    for i, a in enumerate(boxes):
        for j in range(i):
            assert not a.overlaps(boxes[j]), (labels[i].get_text(), labels[j].get_text())
    # beside its point: the box of a 2-D name does not cover the point it names
    for label, box in zip(labels, boxes):
        if hasattr(label, 'xy'):
            x, y = ax.transData.transform(np.asarray(label.xy, float))
            assert not box.contains(x, y), label.get_text()
