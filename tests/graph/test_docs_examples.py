"""Every Python example in the documentation runs as a saved script (``python file.py``, as a
reader runs it: ``python -c`` or an import would hide a missing ``if __name__ ==
'__main__':`` guard, which worker processes need).

tests/graph/test_docs.py runs every block of the tutorials, the how-to pages and README.md, in
order. This module runs the ``python`` blocks of every other page (reference, concepts,
operations, ...), each page's in order in one scratch folder holding ``config/``, with the
blocks titled with a file name written first; a block preceded by ``<!-- not run: REASON -->``
is skipped.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from support.paths import REPO

DOCS = REPO / 'docs'
RUN_BY_TEST_DOCS = ('tutorials', 'how-to')
"""Folders whose pages tests/graph/test_docs.py runs whole (with README.md)."""
FENCE = re.compile(r'^(?P<skip><!-- not run: [^>]+ -->\n)?```(?P<lang>[a-z]*)(?P<attrs>[^\n]*)\n'
                   r'(?P<body>.*?)^```\s*$', re.MULTILINE | re.DOTALL)
TITLE = re.compile(r'title="([^"]+)"')


def python_pages() -> list[Path]:
    """The pages outside :data:`RUN_BY_TEST_DOCS` with a ``python`` block."""
    return sorted(page for page in DOCS.rglob('*.md')
                  if page.relative_to(DOCS).parts[0] not in RUN_BY_TEST_DOCS
                  and any(m['lang'] == 'python' for m in FENCE.finditer(page.read_text())))


def test_every_python_block_of_the_docs_is_run_somewhere() -> None:
    """A page with a Python example is either run whole by test_docs or here; the runner
    below sees the fences the site renders (one page known to hold an example)."""
    pages = python_pages()
    assert DOCS / 'reference' / 'components.md' in pages
    for page in DOCS.rglob('*.md'):
        text = page.read_text()
        blocks = [m for m in FENCE.finditer(text) if m['lang'] == 'python']
        fences = re.findall(r'^```python', text, re.MULTILINE)
        assert len(blocks) == len(fences), f'{page}: a python fence not parsed'


@pytest.mark.parametrize('page', [pytest.param(p, id=str(p.relative_to(DOCS)))
                                  for p in python_pages()])
def test_python_examples_run_as_saved_scripts(page: Path, tmp_path: Path) -> None:
    work = tmp_path / 'work'
    work.mkdir()
    (work / 'config').symlink_to(REPO / 'config')
    ran = 0
    text = page.read_text(encoding='utf-8')
    for match in FENCE.finditer(text):
        line = text.count('\n', 0, match.start()) + 1
        title = TITLE.search(match['attrs'])
        if match['skip']:
            continue
        if title:
            (work / title.group(1)).write_text(match['body'], encoding='utf-8')
        elif match['lang'] == 'python':
            script = work / f'example_{line}.py'
            script.write_text(match['body'], encoding='utf-8')
            proc = subprocess.run([sys.executable, str(script)], cwd=work, capture_output=True,
                                  text=True, timeout=600, stdin=subprocess.DEVNULL)
            assert proc.returncode == 0, (f'{page.name}:{line}: exit {proc.returncode}\n'
                                          f'{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}')
            ran += 1
    assert ran >= 1
