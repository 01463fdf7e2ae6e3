"""MkDocs hook (``hooks:`` in mkdocs.yml): fill the generated tables at build time.

A page holds a marker line ``<!-- generated: NAME -->`` where a table generated from the
code goes (``cli``, ``parameters``, ``topics``: :mod:`trust_av.cli.reference`).
"""

from __future__ import annotations

from typing import Any

from trust_av.cli.reference import fill


def on_page_markdown(markdown: str, **_: Any) -> str:
    """Replace every marker line of a page with its generated table."""
    return fill(markdown)
