"""The README is a front page that works: its Python example runs as written, it stays short
(everything a user needs has a page of its own in docs/), and docs/index.md lists every page."""
import os
import pathlib
import re
import subprocess
import sys

from conftest import REPO

README = pathlib.Path(REPO, 'README.md')
#: about a screen and a half of scrolling: more belongs in docs/
MAX_README_LINES = 250


def test_the_readme_python_example_runs_as_written(tmp_path):
    example = re.findall(r'```python\n(.*?)```', README.read_text(encoding='utf-8'), re.S)[0]
    script = tmp_path / 'example.py'
    script.write_text(example + '\nassert tau.shape == (len(t), 1) and abs(tau).max() > 1.0\n',
                      encoding='utf-8')
    run = subprocess.run([sys.executable, str(script)], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr


def test_the_readme_is_a_front_page():
    lines = README.read_text(encoding='utf-8').count('\n')
    assert lines <= MAX_README_LINES, f'README.md has {lines} lines: move details to docs/'
    text = README.read_text(encoding='utf-8')
    assert './dev run' in text and './dev test' in text       # the two commands
    assert '](docs/index.md)' in text


def test_the_docs_index_lists_every_page():
    docs = pathlib.Path(REPO, 'docs')
    index = (docs / 'index.md').read_text(encoding='utf-8')
    pages = sorted(p.name for p in docs.glob('*.md') if p.name != 'index.md')
    missing = [page for page in pages if f']({page}' not in index]
    assert not missing, f'docs/index.md does not say what these answer: {missing}'
    for target in re.findall(r'\]\(([^)#]+)', index):
        assert os.path.exists(docs / target), f'docs/index.md links to a missing {target}'
