"""Progress bars that suit where they go: tqdm's bar on a terminal; in a log file (a batch job's output,
a redirect) a plain line every LOG_INTERVAL seconds, since a bar redrawn with carriage returns is one
endless line there (a SLURM log of a day's run held megabytes of them)."""
from __future__ import annotations

import sys

from tqdm import tqdm

LOG_INTERVAL = 60.0  # seconds between progress lines in a log


class _Lines:
    """A file for tqdm that turns its redraws (carriage return, bar) into lines, dropping its erasures."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> None:
        for line in text.replace("\r", "\n").split("\n"):
            if line.strip():
                self.stream.write(line.rstrip() + "\n")

    def flush(self) -> None:
        self.stream.flush()


def progress_bar(iterable=None, **options) -> tqdm:
    """``tqdm(iterable, **options)`` on stderr: as given on a terminal, as periodic lines elsewhere."""
    stream = options.pop("file", sys.stderr)
    if not (hasattr(stream, "isatty") and stream.isatty()):
        options.setdefault("mininterval", LOG_INTERVAL)
        options["dynamic_ncols"] = False
        stream = _Lines(stream)
    return tqdm(iterable, file=stream, **options)
