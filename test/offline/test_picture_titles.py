"""The titles of ``cog_id_inspect --plot``'s picture are whole: a long mechanism name, a long
trajectory file name (the subtitle ``6 snapshots of <file>``) or a long warning is wrapped to
the figure's width, and the figure grows by the lines added, so the drawing keeps its room.

Issue: "the inspect picture's subtitle is cut off": ``fig.suptitle`` neither wraps nor
makes room, and constrained layout centres a wide title, so its ends fell outside the
picture. The picture is the one ``draw_mechanism`` saves, drawn again on an Agg canvas to
measure where its texts are.
"""
import pathlib

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import pytest

from cog_id_ros import Mechanism
from cog_id_ros.offline import figure_text, mechanism_plot

CONFIG = pathlib.Path(__file__).resolve().parents[2] / 'config'
LONG_FILE = 'paper_four_bar_target_measured_on_the_test_bench_2024-05-17_run_0042_after_recalibration.csv'
LONG_NAME = 'a_mechanism_whose_name_runs_on_' * 4


def saved_figure(monkeypatch, tmp_path, mech, **kwargs):
    """The Figure draw_mechanism saves for ``mech`` at its assembled pose, drawn."""
    saved = []
    savefig = Figure.savefig

    def keep(self, *args, **kw):
        saved.append(self)
        return savefig(self, *args, **kw)

    monkeypatch.setattr(Figure, 'savefig', keep)
    mechanism_plot.draw_mechanism(str(tmp_path / 'pose.png'), mech, mech.assembled_coordinates,
                                  **kwargs)
    assert len(saved) == 1
    fig = saved[0]
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return fig, canvas.get_renderer()


def texts_outside(fig, renderer):
    """The texts of the figure (its titles, the axes' title and labels) not wholly inside it."""
    width, height = fig.bbox.width, fig.bbox.height
    ax = fig.axes[0]
    texts = list(fig.texts) + [ax.title, ax.xaxis.label, ax.yaxis.label]
    return [(t.get_text(), box.x0, box.x1, box.y0, box.y1)
            for t in texts if t.get_text()
            for box in [t.get_window_extent(renderer)]
            if box.x0 < -0.5 or box.x1 > width + 0.5 or box.y0 < -0.5 or box.y1 > height + 0.5]


@pytest.mark.parametrize('config', ['paper_four_bar_a.yaml', 'stewart_6ups.yaml'])
@pytest.mark.parametrize('title, subtitle, warning', [
    (None, f'6 snapshots of {LONG_FILE}', None),
    (f'{LONG_NAME}: 1 DOF, 3 links, 1 loop (planar), assembled pose', None,
     'WARNING: the assembly moved joint1, joint2, joint4, joint5 and 7 more far from '
     'initial_positions: another branch?'),
])
def test_long_titles_are_wrapped_inside_the_picture(monkeypatch, tmp_path, config, title,
                                                    subtitle, warning):
    mech = Mechanism.from_params_file(CONFIG / config)
    fig, renderer = saved_figure(monkeypatch, tmp_path, mech, title=title, subtitle=subtitle,
                                 warning=warning)
    assert texts_outside(fig, renderer) == []
    joined = ''.join(''.join(t.get_text().split()) for t in fig.texts)
    assert ''.join((subtitle or title).split()) in joined     # all of it, wrapped
    if warning:
        assert ''.join(fig.axes[0].get_title().split()) == ''.join(warning.split())


def test_the_drawing_keeps_its_room_under_a_wrapped_title(monkeypatch, tmp_path):
    """The figure grows by the lines a wrap adds: the axes keep their height, and the
    x label stays clear of the legend below it (it was drawn under the legend when the
    title took the room)."""
    mech = Mechanism.from_params_file(CONFIG / 'paper_four_bar_a.yaml')
    short, r1 = saved_figure(monkeypatch, tmp_path, mech, subtitle='6 snapshots of m.csv')
    monkeypatch.undo()
    long_, r2 = saved_figure(monkeypatch, tmp_path, mech, subtitle=f'6 snapshots of {LONG_FILE}')
    assert long_.get_size_inches()[1] > short.get_size_inches()[1]
    heights = [fig.axes[0].get_window_extent(r).height for fig, r in ((short, r1), (long_, r2))]
    assert heights[1] == pytest.approx(heights[0], rel=0.05)
    label = long_.axes[0].xaxis.label.get_window_extent(r2)
    legend = long_.legends[0].get_window_extent(r2)
    assert not label.overlaps(legend)


def test_a_word_wider_than_the_figure_is_cut_after_a_separator():
    fig = Figure(figsize=(4.0, 3.0), dpi=90)
    text = figure_text.wrapped(fig, f'snapshots of {LONG_FILE}', 11)
    lines = text.split('\n')
    assert ''.join(lines).replace('snapshots of', 'snapshots of ') == f'snapshots of {LONG_FILE}'
    assert len(lines) >= 3 and all(line[-1] in '_-./' for line in lines[1:-1]), lines
