"""An mkdocs hook (mkdocs.yml, ``hooks:``): a guide page states a figure of docs/results.json as
``{{ results.KEY }}`` (e.g. ``{{ results.mre.landmark-v3 }}``), and the site shows the file's value there, so a
figure measured again changes every page that states it. A KEY the file does not hold fails the build.
tests/test_docs_figures.py reads the pages through the same :func:`render`. Standard library only."""
from __future__ import annotations

import json
import re
from pathlib import Path

RESULTS = Path(__file__).resolve().parents[1] / "results.json"
PLACEHOLDER = re.compile(r"\{\{\s*results\.([\w.\-]+?)\s*\}\}")


def render(markdown: str, figures: dict | None = None) -> str:
    """``markdown`` with every ``{{ results.KEY }}`` replaced by the value of figure KEY; KeyError naming an
    unknown KEY."""
    figures = json.loads(RESULTS.read_text())["figures"] if figures is None else figures

    def value(match: re.Match) -> str:
        key = match.group(1)
        if key not in figures:
            raise KeyError(f"{{{{ results.{key} }}}}: docs/results.json has no figure {key!r}")
        return figures[key]["value"]

    return PLACEHOLDER.sub(value, markdown)


def on_page_markdown(markdown: str, page, config, files) -> str:
    """mkdocs' event: each page's Markdown before it is converted."""
    return render(markdown)
