"""docs/results.json written by the benchmarks that measure its figures: ``record`` sets one figure's value
with the command that measured it, today's date and this machine's CPU (the benchmark's ``--record``).

The pages that state a figure are then checked against the file by tests/test_docs_figures.py: after a
run that records, that test names every page whose figure changed.
"""
from __future__ import annotations

import datetime
import json
import shlex
import sys
from pathlib import Path

from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results.json"


def record(key: str, value: str, what: str | None = None, source: str | None = None, path: Path = RESULTS) -> None:
    """Set figure ``key`` of the results file to ``value``, measured now by this process's command line on this
    CPU; ``what`` and ``source`` (the page with the full measurement) replace the entry's own where given (a
    new key needs both). The other figures and their order are kept."""
    data = json.loads(path.read_text())
    entry = data["figures"].get(key, {})
    if not entry and (what is None or source is None):
        raise ValueError(f"{key} is a new figure: give what it is and the page that holds it")
    entry.update(value=value, command=" ".join(["python", *map(shlex.quote, sys.argv)]),
                 date=datetime.date.today().isoformat(), cpu=cpu_description().split(";")[0])
    entry.pop("note", None)  # a note explained the old value
    if what is not None:
        entry["what"] = what
    if source is not None:
        entry["source"] = source
    data["figures"][key] = {field: entry[field] for field in ("value", "what", "command", "date", "cpu", "source")}
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n")
    print(f"docs/results.json: {key} = {value}")
