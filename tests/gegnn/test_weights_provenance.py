"""The meshes the shipped weights were trained on travel with them (issue 57): gegnn/weights/TRAINING_MESHES.tsv,
one row a mesh with its source, commit and licence, in the package beside the weights; and the weights each
started from are named by file and hash."""
import csv
import hashlib
from importlib.resources import files
from pathlib import Path

from gegnn.checkpoint import load_checkpoint
from gegnn.model import PRETRAINED, pretrained_file

ROOT = Path(__file__).resolve().parents[2]


def test_the_package_lists_every_training_and_validation_mesh_with_source_and_licence():
    with (files("gegnn") / "weights" / "TRAINING_MESHES.tsv").open(newline="") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    assert all(r["mesh"] and r["source_repository"] and r["source_path"] and r["licence"] for r in rows)
    used = [r["used_for"].split(" ")[0] for r in rows]
    # pipelines/pretrained/data.sh: 114 man-made and 28 classic meshes train, the 19 of val.txt validate; since
    # landmark-v4 the generated shapes of pipelines/landmark/zoo_meshes.py train too (one row)
    assert (used.count("training"), used.count("validation")) == (143, 19)
    val = {line.strip() for line in (ROOT / "pipelines/pretrained/val.txt").read_text().splitlines()
           if line.strip() and not line.startswith("#")}
    assert {r["mesh"] for r in rows if r["used_for"].startswith("validation")} == {f"dev/{v}" for v in val}


def test_the_licence_readme_and_model_card_point_to_it_not_to_a_folder_users_lack():
    for page in ("LICENSE", "README.md", "docs/model-card.md"):
        text = (ROOT / page).read_text()
        assert "TRAINING_MESHES.tsv" in text, page
        assert "shared/meshes/_provenance" not in text and "shared/meshes/MANIFEST" not in text, page


def test_the_wheel_takes_it_with_the_weights():
    """pyproject's wheel.packages copies a package's data files: scikit-build-core's own file mapping (a private
    function of the build backend, so the test skips where it moved) lists the file."""
    import pytest

    pathutil = pytest.importorskip("scikit_build_core.build._pathutil")
    if not hasattr(pathutil, "packages_to_file_mapping"):
        pytest.skip("scikit-build-core moved its file mapping")
    mapping = pathutil.packages_to_file_mapping(packages={"gegnn": str(ROOT / "gegnn")}, platlib_dir=Path("/wheel"),
                                                include=[], src_exclude=[], target_exclude=[], build_dir="build/x",
                                                mode="default")
    assert "/wheel/gegnn/weights/TRAINING_MESHES.tsv" in mapping.values()


def test_the_weights_a_shipped_model_started_from_are_a_file_and_its_hash_not_a_name_that_moves():
    """landmark-v4 started from landmark-v3's file, landmark-v3 (and its point-cloud twin, the same
    train_config) from landmark-v2's, each when "landmark" named it: each records that file's path and sha256,
    which the shipped file matches. No shipped file records a shipped model's name, whose file changes with each
    default."""
    recorded = {}
    for name in PRETRAINED:
        with pretrained_file(name) as path:
            recorded[name] = load_checkpoint(path).metadata["train_config"]
    assert not [name for name, config in recorded.items() if config.get("init") in PRETRAINED]
    assert recorded["landmark"]["init"] == "gegnn/weights/gegnn-landmark-v3.safetensors"
    for name in ("landmark-v3", "points"):
        assert recorded[name]["init"] == "gegnn/weights/gegnn-landmark-v2.safetensors" and recorded[name]["init_sha256"]
    for name, config in recorded.items():
        if config.get("init_sha256"):
            assert hashlib.sha256((ROOT / config["init"]).read_bytes()).hexdigest() == config["init_sha256"], name
