"""MkDocs hooks (mkdocs.yml ``hooks:``): the Results section lists docs/results/, and docstrings' Sphinx roles read.

Every page under docs/results/ appears in the site's Results section. The result pages are written by
``scripts/render_results.py``, one per reproduced table, with an index; listing them here means a new table
reaches the navigation without an edit to mkdocs.yml. The section keeps the pages mkdocs.yml names first, then
the generated index, then the tables in file-name order.
"""

from __future__ import annotations

import re
from pathlib import Path

RESULTS_SECTION = "Results"
RESULTS_DIR = "results"
INDEX = f"{RESULTS_DIR}/index.md"
# The package's docstrings are reStructuredText-flavoured (``:class:`X```, a paragraph ending in ``::`` before a
# literal block); mkdocstrings renders them as Markdown, which would print the role names and the double colon.
ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const|ref):<code>~?")
LITERAL_INTRO = re.compile(r"::</p>(\s*<div class=\"(?:language-|highlight))")


def _listed(entries: list) -> set[str]:
    """The page paths already named in a nav section (bare paths and ``{title: path}`` entries)."""
    paths = set()
    for entry in entries:
        values = entry.values() if isinstance(entry, dict) else [entry]
        paths.update(value for value in values if isinstance(value, str))
    return paths


def result_pages(docs_dir: Path, listed: set[str]) -> list[str]:
    """The docs/results/*.md pages (as docs-relative paths) that the nav does not name yet, sorted."""
    folder = docs_dir / RESULTS_DIR
    if not folder.is_dir():
        return []
    pages = (f"{RESULTS_DIR}/{path.relative_to(folder).as_posix()}" for path in folder.rglob("*.md"))
    return sorted((page for page in pages if page not in listed), key=lambda page: (page != INDEX, page))


def on_config(config):
    for entry in config["nav"] or []:
        if isinstance(entry, dict) and RESULTS_SECTION in entry and isinstance(entry[RESULTS_SECTION], list):
            section = entry[RESULTS_SECTION]
            section.extend(result_pages(Path(config["docs_dir"]), _listed(section)))
    return config


def readable_roles(html: str) -> str:
    """``html`` with Sphinx roles (and their ``~``) dropped before inline code, ``::`` before a code block as ``:``."""
    return LITERAL_INTRO.sub(r":</p>\1", ROLE.sub("<code>", html))


def on_page_content(html, page, config, files):
    return readable_roles(html)
