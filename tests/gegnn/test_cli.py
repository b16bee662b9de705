import csv

import numpy as np
import trimesh
from click.testing import CliRunner
from gegnn_stores import ellipsoid

from gegnn.cli import main

SMALL = ["--channels", "16", "--blocks", "1,1,1,1,1", "--pairs-per-mesh", "200"]


def test_train_eval_query(tiny_store, tmp_path):
    runner = CliRunner()
    run = tmp_path / "run"
    result = runner.invoke(main, ["train", tiny_store, "--run", str(run), "--epochs", "2", "--batch-size", "2",
                                  "--lr", "1e-3", "--seed", "1", "--device", "cpu", "--aggr", "mean",
                                  "--plain-grid-pool", *SMALL])
    assert result.exit_code == 0, result.output
    assert "epoch 1 step 4" in (run / "train.log").read_text()
    result = runner.invoke(main, ["train", tiny_store, "--run", str(run), "--epochs", "3", "--resume"])
    assert result.exit_code == 0, result.output
    with open(run / "metrics.csv") as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == ["0", "1", "2"]

    result = runner.invoke(main, ["eval", str(run / "best.safetensors"), tiny_store, "--device", "cpu",
                                  "--csv", str(tmp_path / "eval.csv")])
    assert result.exit_code == 0, result.output
    lines = result.stdout.strip().splitlines()  # the progress bar goes to stderr
    assert lines[0].split() == ["mesh", "vertices", "pairs", "MRE", "%"] and lines[-1].startswith("overall")
    assert len(lines) == 6  # header, four meshes, overall
    with open(tmp_path / "eval.csv") as f:
        rows = list(csv.DictReader(f))
    # What the command wrote is what the library computes for that checkpoint, mesh by mesh.
    from gegnn import GeGnn
    from gegnn.training.loop import evaluate_store

    expected = evaluate_store(GeGnn.from_checkpoint(run / "best.safetensors"), tiny_store)
    assert [r["mesh_id"] for r in rows] == [r["mesh_id"] for r in expected] + ["overall"]
    for got, want in zip(rows, expected):
        assert float(got["mre"]) == want["mre"] and int(got["pairs"]) == want["pairs"]
    overall = sum(r["sum"] for r in expected) / sum(r["pairs"] for r in expected)
    assert float(rows[-1]["mre"]) == overall and 0 < overall < 1

    v, f = ellipsoid()
    trimesh.Trimesh(v * 3.0, f, process=False).export(tmp_path / "m.obj")
    result = runner.invoke(main, ["query", str(run / "last.safetensors"), str(tmp_path / "m.obj"),
                                  "--source", "5", "-o", str(tmp_path / "field.npy")])
    assert result.exit_code == 0, result.output
    assert np.load(tmp_path / "field.npy").shape == (len(v),)


def test_help_lists_commands():
    result = CliRunner().invoke(main, ["--help"])
    assert result.exit_code == 0 and {"train", "eval", "query"} <= set(result.output.split())


def test_query_biharmonic_compares_with_the_exact_biharmonic_field(tmp_path):
    from geodata.biharmonic import biharmonic_distances
    from geodata.mesh import Mesh

    v, f = ellipsoid()
    trimesh.Trimesh(v * 3.0, f, process=False).export(tmp_path / "m.obj")
    result = CliRunner().invoke(main, ["query", "--pretrained", "biharmonic", str(tmp_path / "m.obj"),
                                       "--source", "5", "--exact", "-o", str(tmp_path / "field.npy")])
    assert result.exit_code == 0, result.output
    assert "biharmonic distance from 5" in result.output
    mre = float(result.output.split("mean relative error vs exact: ")[1].split("%")[0])
    exact = biharmonic_distances(Mesh(v * 3.0, f), [5])[0]
    pred = np.load(tmp_path / "field.npy")
    keep = np.arange(len(v)) != 5
    assert abs(100 * np.mean(np.abs(pred - exact)[keep] / (exact[keep] + 3e-3)) - mre) < 0.01 and mre < 5
