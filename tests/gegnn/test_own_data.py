"""docs/own-data.md runs as written (issue 57): its ```bash blocks, in order, in one shell, in an empty folder, on
the six sample soups of `geodata examples` (about two minutes on 2 cores)."""
import os
import re
import subprocess
import sys
from pathlib import Path

PAGE = Path(__file__).resolve().parents[2] / "docs" / "own-data.md"


def page_commands() -> str:
    """The page's ```bash blocks, in order: the script the test runs and a reader types."""
    return "\n".join(re.findall(r"```bash\n(.*?)```", PAGE.read_text(), flags=re.S))


def test_the_page_walks_from_a_folder_to_a_model_with_the_presets_options():
    script = page_commands()
    assert "gegnn train data/train.zarr --val data/val.zarr --run runs/mine --model landmark --init landmark" in script
    for step in ("geodata prepare", "geodata info", "gegnn eval runs/mine/best.safetensors",
                 "gegnn eval landmark", "gegnn query runs/mine/best.safetensors", "gegnn view runs/mine",
                 "gegnn export runs/mine/best.safetensors"):
        assert step in script, step


def test_the_pages_commands_run_as_written(tmp_path):
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
           "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "2")}
    result = subprocess.run(["bash", "-euo", "pipefail", "-c", page_commands()], cwd=tmp_path, env=env,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    for made in ("runs/mine/best.safetensors", "mug.png", "mug.html", "mine.safetensors"):
        assert (tmp_path / made).is_file(), made
    log = [line.split(" ", 2)[2] for line in (tmp_path / "runs/mine/train.log").read_text().splitlines()]
    assert log[0].startswith("model: preset landmark: GeGnn (landmark-guided, K = 256, 64 channels")
    assert "fine-tuned from landmark" in log[0] and any(line.startswith("estimate: ") for line in log)
    evals = [line for line in result.stdout.splitlines() if line.startswith("overall")]
    assert len(evals) == 2  # the new model and the shipped one, on the same held-out meshes
    assert "4 ok" in result.stdout  # geodata info of the training store
