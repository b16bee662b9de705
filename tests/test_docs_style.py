"""The guide pages (README.md, docs/*.md; not the lab notes in docs/notes/) speak to users: no issue numbers,
commit hashes, or words about how the project is developed (sessions, leases, agents, "this virtual machine").
Such history goes to docs/notes/ or CHANGELOG.md, which names features, not issues."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GUIDES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]

HEX = r"(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}"  # a commit hash: hex digits, a letter and a digit
LAB_WORDS = {
    "an issue number": r"\bissues? #?\d+|(?<![\w-])#\d{2,}\b",  # not another project's (libigl#1013)
    "a commit hash": rf"`{HEX}`|\((?:commits? )?{HEX}[),;\s]|\bcommits? {HEX}\b",
    "a session": r"\bsessions?\b",
    "a lease": r"\bleases?\b|\blent\b",
    "an agent": r"\bagents?\b",
    "this virtual machine": r"\bthis (?:\S+ )?virtual machine\b",
}


def lab_words(text: str) -> list[tuple[int, str, str]]:
    """(line, what, the words) of every lab-notebook phrase in ``text``."""
    return [(text.count("\n", 0, m.start()) + 1, what, m.group(0))
            for what, pattern in LAB_WORDS.items() for m in re.finditer(pattern, text, flags=re.I)]


@pytest.mark.parametrize("page", GUIDES)
def test_a_guide_page_holds_no_lab_notebook_words(page):
    found = lab_words((ROOT / page).read_text(encoding="utf-8"))
    assert not found, f"{page}: " + "; ".join(f"line {n}: {what} ({words!r})" for n, what, words in found)


def test_the_changelog_names_features_not_issues():
    found = [hit for hit in lab_words((ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))
             if hit[1] in ("an issue number", "a commit hash")]
    assert not found, found


@pytest.mark.parametrize("text", [
    "Since issue 58 the solver", "Issue 55, item 1:", "(issue #12)", "on commit 87c707c (0.3.1", "(843ac6c)",
    "`df8002f`", "(commits 843ac6c and", "between sessions", "the H200 lease", "No GPU was lent",
    "other agents' work", "on this virtual machine", "Times on this 2-core virtual machine vary"])
def test_the_check_finds_lab_notebook_words(text):
    assert lab_words(text), text


@pytest.mark.parametrize("text", [
    "dragon-4af53808, 5224 vertices", "| dragon-fd9671e3 | 4762 |", "`k256-rounds16-vsp-v2`", "release 0.3.1",
    "sha256 5df31469...", "(1234567 pairs)", "(3,854,999 pairs)", "`abcdefg`", "a 2-core AMD EPYC virtual machine",
    "the issue tracker", "pleased", "a tissue", "(decimated-max, 5,272 vertices)", "`0.3.3`",
    "the libigl#1013 class of bug", "races, zarr-python#1435)"])
def test_the_check_passes_legitimate_text(text):
    assert not lab_words(text), lab_words(text)
