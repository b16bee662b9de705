"""Progress in a log file is lines, not a bar redrawn with carriage returns."""
import io

import geodata.progress as gprogress


def test_a_log_gets_periodic_lines_and_a_terminal_the_bar(monkeypatch):
    log = io.StringIO()
    for _ in gprogress.progress_bar(range(50), desc="work", file=log):
        pass
    text = log.getvalue()
    assert "\r" not in text and text.endswith("\n")
    lines = text.splitlines()
    # the first and the last state (LOG_INTERVAL, 60 s, apart at most in between): not one per item
    assert 2 <= len(lines) <= 3 and lines[0].startswith("work:   0%") and "50/50" in lines[-1]

    class Terminal(io.StringIO):
        def isatty(self):
            return True
    tty = Terminal()
    for _ in gprogress.progress_bar(range(5), desc="work", file=tty, mininterval=0):
        pass
    assert "\r" in tty.getvalue()  # tqdm's own bar, redrawn in place
