"""Titles that fit their figure: matplotlib neither wraps a title nor makes room for a
wide one (constrained layout centres it and the figure's edges cut both ends).
:func:`suptitle` and :func:`axes_title` break a title's lines where they would be wider
than the figure, and make the figure taller by the lines they add, so that the drawing
keeps its size.

Widths are measured with the Agg renderer at the figure's resolution, in the title's font;
lines break between words, and a word wider than the room alone (a long file name) after
one of ``_-./`` in it where it can, else between characters.
"""

#: the share of the figure's width a title may take (the rest: a margin on each side)
TITLE_SHARE = 0.96
#: an axes title's share: an axes is narrower than its figure and off its centre
AXES_TITLE_SHARE = 0.8
#: height of a line of text, in font sizes (matplotlib's default line spacing, 1.2)
LINE_HEIGHT = 1.2
_WORD_BREAKS = '_-./'


def suptitle(fig, text, fontsize):
    """``fig.suptitle(text)`` at ``fontsize`` points, wrapped to the figure's width."""
    fig.suptitle(_fitted(fig, text, fontsize, TITLE_SHARE), fontsize=fontsize)


def axes_title(fig, ax, text, fontsize, **style):
    """``ax.set_title(text, **style)`` at ``fontsize`` points, wrapped likewise."""
    ax.set_title(_fitted(fig, text, fontsize, AXES_TITLE_SHARE), fontsize=fontsize, **style)


def _fitted(fig, text, fontsize, share):
    """``text`` wrapped (:func:`wrapped`); ``fig`` made taller by the lines added."""
    fitted = wrapped(fig, text, fontsize, share)
    added = fitted.count('\n') - text.count('\n')
    if added:
        width, height = fig.get_size_inches()
        fig.set_size_inches(width, height + added * LINE_HEIGHT * fontsize / 72.0)
    return fitted


def wrapped(fig, text, fontsize, share=TITLE_SHARE):
    """``text`` with its lines broken so that each, drawn at ``fontsize`` points in
    matplotlib's default font, is at most ``share`` of the width of ``fig``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.font_manager import FontProperties

    renderer = FigureCanvasAgg(fig).get_renderer()
    font = FontProperties(size=fontsize)
    room = share * fig.bbox.width

    def fits(line):
        return renderer.get_text_width_height_descent(line, font, ismath=False)[0] <= room

    lines = []
    for paragraph in text.split('\n'):
        line = ''
        for word in paragraph.split(' '):
            trial = f'{line} {word}' if line else word
            if fits(trial):
                line = trial
                continue
            if line:
                lines.append(line)
            while not fits(word):              # a word wider than the room: cut it
                cut = _cut(word, fits)
                lines.append(word[:cut])
                word = word[cut:]
            line = word
        lines.append(line)
    return '\n'.join(lines)


def _cut(word, fits):
    """Where to cut ``word``: after its last ``_-./`` that leaves a start that fits, else
    after the longest start that fits (at least one character)."""
    low, high = 1, len(word)
    while low < high:
        middle = (low + high + 1) // 2
        if fits(word[:middle]):
            low = middle
        else:
            high = middle - 1
    at = max(word.rfind(char, 0, low) for char in _WORD_BREAKS)
    return at + 1 if at > 0 else low
