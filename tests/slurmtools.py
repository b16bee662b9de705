"""The test SLURM clusters' fixture, shared by the single-node and the two-node cluster tests."""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def running_cluster(script_name: str, tools: tuple, missing: str, needs_root: str, name: str):
    """Start the cluster of ``scripts/<script_name>`` for the tests and stop it after them (a generator for a
    fixture). Where it cannot start (``tools`` missing, not root, the script failed): a failure under CI=true,
    else a skip, with the reason."""
    script = str(ROOT / "scripts" / script_name)
    path = f"{os.environ.get('PATH', '')}:/usr/sbin:/sbin"  # the daemons live in sbin
    if not all(shutil.which(t, path=path) for t in tools):
        why = missing
    elif os.geteuid() != 0:
        why = needs_root
    else:
        start = subprocess.run([script, "start"], capture_output=True, text=True)
        why = None if start.returncode == 0 else f"{name} did not start: {start.stderr.strip()}"
    if why:
        if os.environ.get("CI") == "true":
            pytest.fail(why)
        pytest.skip(why)
    yield
    subprocess.run([script, "stop"], check=True)
