"""The figures of docs/results.json as the guide pages state them: each such figure is written into the page
between two HTML comments that name its key,

    the default is at **<!-- results.mre.landmark-v4 -->0.25%<!-- /results -->** on held-out meshes

so that the page reads right wherever it is read (a forge, an editor, the site: the comments show nowhere),
and the file stays the one source of each figure: ``python docs/_ext/results_hook.py`` writes every marked
figure of README.md and docs/*.md from the file (``benchmarks/results.py``'s ``record`` does it after each
figure it records), and the site's build (mkdocs.yml, ``hooks:``) and tests/test_docs_figures.py fail on a
page whose marked figure differs from the file, naming it. Standard library only.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "docs" / "results.json"
MARKED = re.compile(r"<!-- results\.([\w.\-]+?) -->(.*?)<!-- /results -->", re.S)


def figures(path: Path = RESULTS) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))["figures"]


def _value(key: str, figures_: dict) -> str:
    if key not in figures_:
        raise KeyError(f"<!-- results.{key} -->: docs/results.json has no figure {key!r}")
    return figures_[key]["value"]


def write(markdown: str, figures_: dict) -> str:
    """``markdown`` with every marked figure set to the file's value (KeyError naming an unknown key)."""
    return MARKED.sub(lambda m: f"<!-- results.{m.group(1)} -->{_value(m.group(1), figures_)}<!-- /results -->",
                      markdown)


def stale(markdown: str, figures_: dict) -> list[tuple[int, str, str, str]]:
    """(line, key, the page's figure, the file's) of every marked figure that differs from the file."""
    return [(markdown.count("\n", 0, m.start()) + 1, m.group(1), m.group(2), _value(m.group(1), figures_))
            for m in MARKED.finditer(markdown) if m.group(2) != _value(m.group(1), figures_)]


def render(markdown: str) -> str:
    """``markdown`` as a reader sees it: the marks gone, their figures in place."""
    return MARKED.sub(lambda m: m.group(2), markdown)


def pages(root: Path = ROOT) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def write_pages(root: Path = ROOT, results: Path = RESULTS) -> list[str]:
    """Write every marked figure of README.md and docs/*.md under ``root`` from ``results``: the pages changed."""
    figures_ = figures(results)
    changed = []
    for page in pages(root):
        text = page.read_text(encoding="utf-8")
        new = write(text, figures_)
        if new != text:
            page.write_text(new, encoding="utf-8")
            changed.append(str(page.relative_to(root)))
    return changed


def on_page_markdown(markdown: str, page, config, files) -> str:
    """mkdocs' event: each page's Markdown before it is converted; a stale marked figure fails the build."""
    found = stale(markdown, figures())
    if found:
        raise ValueError(f"{page.file.src_path}: " + "; ".join(
            f"line {line}: {key} is {said} here, {value} in docs/results.json" for line, key, said, value in found)
            + " (python docs/_ext/results_hook.py writes them)")
    return markdown


if __name__ == "__main__":
    written = write_pages()
    print(f"figures of docs/results.json written into {', '.join(written) if written else 'no page (all current)'}")
