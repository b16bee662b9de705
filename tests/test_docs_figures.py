"""The key figures of README.md and the docs agree with docs/results.json, one value per fact.

docs/results.json holds each figure once, with the command, date and CPU that measured it. A guide page in
docs/ states one in place between marks naming its key (``<!-- results.KEY -->0.25%<!-- /results -->``), which
docs/_ext/results_hook.py writes from the file and checks; README.md states the values unmarked. Each CLAIM below
finds where a page states a figure, read as a reader sees it (the regex's group is the figure, its surroundings
say which model and what quantity); the test fails when a page states it differently, or when a claim no longer
finds its sentence (a rewritten page must be tied to the file again, not silently drop out of the check).
"""
import importlib.util
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results.json"
HOOK = ROOT / "docs" / "_ext" / "results_hook.py"
_spec = importlib.util.spec_from_file_location("results_hook", HOOK)
results_hook = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(results_hook)

# (figure key, page, pattern with one group: the figure as the page states it)
CLAIMS = [
    # accuracy of each shipped model
    ("mre.landmark-v4", "README.md", r"`GeGnn\.pretrained\(\)`: landmark-v4, K = 256 landmarks by virtual sources \(the default\) \| \*\*([\d.]+%)\*\*"),
    ("mre.landmark-v4", "docs/index.md", r"`GeGnn\.pretrained\(\)`: landmark-v4, K = 256 landmarks by virtual sources \(the default\) \| \*\*([\d.]+%)\*\*"),
    ("mre.landmark-v4", "docs/queries.md", r"`GeGnn\.pretrained\(\)`: landmark-v4, K = 256 landmarks by virtual sources \(the default\) \| \*\*([\d.]+%)\*\*"),
    ("mre.landmark-v4", "docs/model-card.md", r"`gegnn/weights/gegnn-landmark-v4\.safetensors` \| landmark-guided GeGnn, K = 256, fields by virtual sources, trained with tubes, tori and knots \| \*\*([\d.]+%)\*\*"),
    ("mre.zoo.landmark-v4", "README.md", r"the default is ([\d.]+%) on average and at most"),
    ("mre.zoo.landmark-v3", "docs/benchmarks.md", r"reading 0\.3\.3's, not retrained, ([\d.]+%) on average"),
    ("mre.zoo.landmark-v4", "docs/benchmarks.md", r"trained on them with generated tubes,\n([\d.]+%) and at most"),
    ("mre.landmark-v3", "README.md", r"`GeGnn\.pretrained\(\"landmark-v3\"\)`: the previous default, trained on 0\.3\.2's fields \| ([\d.]+%)"),
    ("mre.landmark-v2", "README.md", r"`GeGnn\.pretrained\(\"landmark-v2\"\)`: K = 256 heat-method landmarks \| ([\d.]+%)"),
    ("mre.landmark-v2", "docs/index.md", r"`GeGnn\.pretrained\(\"landmark-v2\"\)`: K = 256 heat-method landmarks \| ([\d.]+%)"),
    ("mre.landmark-v2", "docs/queries.md", r"`GeGnn\.pretrained\(\"landmark-v2\"\)`: K = 256 heat-method landmarks \| ([\d.]+%)"),
    ("mre.landmark-v2", "docs/model-card.md", r"`gegnn/weights/gegnn-landmark-v2\.safetensors` \| K = 256 heat-method fields \| ([\d.]+%)"),
    # the geodesic table's mean row: eight bold columns to the end of the line (the biharmonic one goes on)
    ("mre.landmark-v2-sequential", "docs/results.md", r"(?m)^\| \*\*mean\*\* \| \| \*\*([\d.]+%)\*\* \|(?: \*\*[\d.]+%\*\* \|){7}$"),
    ("mre.landmark-v2-sequential", "docs/results.md", r"now measures [\d.]+% \(([\d.]+%) below\)"),
    ("mre.landmark-v2", "docs/results.md", r"now measures ([\d.]+%) \([\d.]+% below\)"),
    ("mre.landmark-v1", "README.md", r"`GeGnn\.pretrained\(\"landmark-v1\"\)`: K = 128 \| ([\d.]+%)"),
    ("mre.landmark-v1", "docs/index.md", r"`GeGnn\.pretrained\(\"landmark-v1\"\)`: K = 128 \| ([\d.]+%)"),
    ("mre.landmark-v1", "docs/queries.md", r"`GeGnn\.pretrained\(\"landmark-v1\"\)`: K = 128 \| ([\d.]+%)"),
    ("mre.landmark-v1", "docs/model-card.md", r"`gegnn/weights/gegnn-landmark-v1\.safetensors` \| K = 128 \| ([\d.]+%)"),
    ("mre.paper", "README.md", r"`GeGnn\.pretrained\(\"paper\"\)`: the paper's model \| ([\d.]+%)"),
    ("mre.paper", "docs/index.md", r"`GeGnn\.pretrained\(\"paper\"\)`: the paper's model \| ([\d.]+%)"),
    ("mre.paper", "docs/queries.md", r"`GeGnn\.pretrained\(\"paper\"\)`: the paper's model \| ([\d.]+%)"),
    ("mre.paper", "docs/model-card.md", r"`gegnn/weights/gegnn-classic-v1\.safetensors` \| the paper's model \| ([\d.]+%)"),
    ("mre.paper", "docs/results.md", r"(?m)^\| \*\*mean\*\* \| \| \*\*[\d.]+%\*\* \| \*\*([\d.]+%)\*\* \|(?: \*\*[\d.]+%\*\* \|){6}$"),
    ("mre.heat", "docs/results.md", r"(?m)^\| \*\*mean\*\* \| \|(?: \*\*[\d.]+%\*\* \|){3} \*\*([\d.]+%)\*\* \|(?: \*\*[\d.]+%\*\* \|){4}$"),
    ("mre.biharmonic", "docs/results.md", r"(?m)^\| \*\*mean\*\* \| \| \*\*([\d.]+%)\*\* \|(?: \*\*[\d.]+%\*\* \|){7} [\d.]+ \|$"),
    ("mre.heat", "README.md", r"heat method \(potpourri3d\), same pairs \| ([\d.]+%)"),
    ("mre.heat", "docs/index.md", r"heat method \(potpourri3d\), same pairs \| ([\d.]+%)"),
    ("mre.heat", "docs/queries.md", r"heat method \(potpourri3d\), same pairs \| ([\d.]+%)"),
    ("mre.biharmonic", "README.md", r"predicts \*\*biharmonic\*\* distances to \*\*([\d.]+%)\*\*"),
    ("mre.biharmonic", "docs/queries.md", r"predicts \*\*biharmonic\*\* distances: \*\*([\d.]+%)\*\*"),
    ("mre.biharmonic", "docs/model-card.md", r"learned correction \| \*\*([\d.]+%)\*\* \(biharmonic\)"),
    ("mre.points-v3", "README.md", r"takes point clouds without faces: \*\*([\d.]+%)\*\*"),
    ("mre.points-v3", "docs/queries.md", r"own local triangles,\s+\*\*([\d.]+%)\*\* on clouds"),
    ("mre.points-v3", "docs/queries.md", r"clouds of the validation meshes' vertices, all stored pairs: \*\*([\d.]+%)\*\*"),
    ("mre.points-v3", "docs/model-card.md", r"`gegnn/weights/gegnn-points-v3\.safetensors` \| point clouds[^|]*\| \*\*([\d.]+%)\*\*"),
    ("mre.points-v3", "docs/model-card.md", r"points-v3\.safetensors data/val\.zarr`, 2026-12-07\): \*\*([\d.]+%)\*\*"),
    ("mre.points-v3", "docs/pointclouds.md", r"points-v3\.safetensors data/val\.zarr`, 2026-12-07\): \*\*([\d.]+%)\*\*"),
    ("mre.points-v2", "README.md", r"\(points-v2, heat-method fields: ([\d.]+%);"),
    ("mre.points-v2", "docs/queries.md", r"the point-cloud heat method's fields \(([\d.]+%)\)"),
    ("mre.points-v2", "docs/model-card.md", r"`gegnn/weights/gegnn-points-v2\.safetensors` \| the previous one[^|]*\| ([\d.]+%)"),
    ("mre.points-v2", "docs/model-card.md", r"points-v2\.safetensors data/val\.zarr`, 2026-11-26\): \*\*([\d.]+%)\*\*"),
    ("mre.points-v2", "docs/model-card.md", r"\*\*[\d.]+%\*\* \(points-v2:\n([\d.]+%) when it shipped"),
    ("mre.points-v1", "README.md", r"points-v1,\s+K = 128: ([\d.]+%)\)"),
    ("mre.points-v1", "docs/queries.md", r"`\"points-v1\"` landmark-v1's \(K = 128, ([\d.]+%)\)"),
    ("mre.points-v1", "docs/model-card.md", r"`gegnn/weights/gegnn-points-v1\.safetensors` \| the one before[^|]*\| ([\d.]+%)"),
    ("mre.points-v1", "docs/pointclouds.md", r"\*\*[\d.]+%\*\*\n\(points-v2: [\d.]+%; points-v1: ([\d.]+%)\)"),
    ("mre.points-v2", "docs/pointclouds.md", r"\*\*[\d.]+%\*\*\n\(points-v2: ([\d.]+%); points-v1"),
    # speed-up over the heat method, and the paper model's time
    ("speedup.landmark-v4", "README.md", r"\*\*([\d.]+x)\*\* the heat method"),
    ("speedup.landmark-v4", "docs/queries.md", r"\*\*([\d.]+x)\*\* the heat method"),
    ("speedup.landmark-v3", "docs/model-card.md", r"gives the default 0\.486 s and\n\*\*([\d.]+x)\*\* the heat method"),
    ("speedup.landmark-v2", "docs/results.md", r"The speed-up stated elsewhere \(0\.3\.0: \*\*([\d.]+x)\*\*\)"),
    ("time.paper", "README.md", r"`GeGnn\.pretrained\(\"paper\"\)`: the paper's model \| [\d.]+% \| ([\d.]+ s)"),
    ("time.paper", "docs/index.md", r"`GeGnn\.pretrained\(\"paper\"\)`: the paper's model \| [\d.]+% \| ([\d.]+ s)"),
    ("time.paper", "docs/queries.md", r"`GeGnn\.pretrained\(\"paper\"\)`: the paper's model \| [\d.]+% \| ([\d.]+ s)"),
    ("time.paper", "docs/model-card.md", r"1M random queries 0\.10 s \(the compiled decode\), \*\*([\d.]+ s)\*\* in all"),
    # the shipped models' table (README, docs home, queries): its time column, the bound and the damaged meshes
    ("time.landmark-v4", "README.md", r"`GeGnn\.pretrained\(\)`: landmark-v4, K = 256 landmarks by virtual sources \(the default\) \| \*\*[\d.]+%\*\* \| ([\d.]+ s)"),
    ("time.landmark-v4", "docs/index.md", r"`GeGnn\.pretrained\(\)`: landmark-v4, K = 256 landmarks by virtual sources \(the default\) \| \*\*[\d.]+%\*\* \| ([\d.]+ s)"),
    ("time.landmark-v4", "docs/queries.md", r"`GeGnn\.pretrained\(\)`: landmark-v4, K = 256 landmarks by virtual sources \(the default\) \| \*\*[\d.]+%\*\* \| ([\d.]+ s)"),
    ("time.landmark-v2", "README.md", r"`GeGnn\.pretrained\(\"landmark-v2\"\)`: K = 256 heat-method landmarks \| [\d.]+% \| ([\d.]+ s)"),
    ("time.landmark-v2", "docs/index.md", r"`GeGnn\.pretrained\(\"landmark-v2\"\)`: K = 256 heat-method landmarks \| [\d.]+% \| ([\d.]+ s)"),
    ("time.landmark-v2", "docs/queries.md", r"`GeGnn\.pretrained\(\"landmark-v2\"\)`: K = 256 heat-method landmarks \| [\d.]+% \| ([\d.]+ s)"),
    ("time.landmark-v1", "README.md", r"`GeGnn\.pretrained\(\"landmark-v1\"\)`: K = 128 \| [\d.]+% \| ([\d.]+ s)"),
    ("time.landmark-v1", "docs/index.md", r"`GeGnn\.pretrained\(\"landmark-v1\"\)`: K = 128 \| [\d.]+% \| ([\d.]+ s)"),
    ("time.landmark-v1", "docs/queries.md", r"`GeGnn\.pretrained\(\"landmark-v1\"\)`: K = 128 \| [\d.]+% \| ([\d.]+ s)"),
    ("time.heat", "README.md", r"heat method \(potpourri3d\), same pairs \| [\d.]+% \| ([\d.]+ s)"),
    ("time.heat", "docs/index.md", r"heat method \(potpourri3d\), same pairs \| [\d.]+% \| ([\d.]+ s)"),
    ("time.heat", "docs/queries.md", r"heat method \(potpourri3d\), same pairs \| [\d.]+% \| ([\d.]+ s)"),
    ("mre.bound.heat256", "README.md", r"the landmark lower bound of its 256 heat-method fields alone at ([\d.]+%)"),
    ("mre.bound.heat256", "docs/queries.md", r"bound of landmark-v2's 256 heat-method fields alone, ([\d.]+%)"),
    ("mre.damaged.landmark-v2", "README.md", r"With 15% of the triangles removed and the vertices jittered: ([\d.]+%)"),
    ("mre.damaged.landmark-v2", "docs/queries.md", r"With 15% of the triangles removed and the vertices jittered: ([\d.]+%)"),
    ("mre.damaged.heat", "README.md", r"With 15% of the triangles removed and the vertices jittered: [\d.]+%\s+\(heat method\s+([\d.]+%)"),
    ("mre.damaged.heat", "docs/queries.md", r"With 15% of the triangles removed and the vertices jittered: [\d.]+%\s+\(heat method\s+([\d.]+%)"),
    ("mre.bound.heat256", "docs/results.md", r"(?m)^\| \*\*mean\*\* \| \|(?: \*\*[\d.]+%\*\* \|){2} \*\*([\d.]+%)\*\* \|(?: \*\*[\d.]+%\*\* \|){5}$"),
    ("mre.damaged.landmark-v2", "docs/results.md", r"(?m)^\| \*\*mean\*\* \| \|(?: \*\*[\d.]+%\*\* \|){5} \*\*([\d.]+%)\*\* \|(?: \*\*[\d.]+%\*\* \|){2}$"),
    ("mre.damaged.heat", "docs/results.md", r"(?m)^\| \*\*mean\*\* \| \|(?: \*\*[\d.]+%\*\* \|){7} \*\*([\d.]+%)\*\* \|$"),
    ("time.heat", "docs/model-card.md", r"\*\*[\d.]+ s\*\* in all, against\n([\d.]+ s) for the heat method"),
    # what training on one's own meshes costs (docs/own-data.md's estimates rest on these)
    ("prepare.mesh.cpu", "docs/own-data.md", r"\| `geodata prepare --pairs 100000` \| ([\d.]+ s) \| mesh"),
    ("train.fields.landmark.cpu", "docs/own-data.md",
     r"\| landmark fields \(K = 256 by virtual sources, the preset's; 4 draws\), before the first step \| ([\d.]+ s) \|"),
    ("train.step.landmark.cpu", "docs/own-data.md", r"\| a training step of `--model landmark` \(4 meshes, 20,000 pairs each\) \| ([\d.]+ s) \|"),
    ("train.step.paper256.cpu", "docs/own-data.md", r"the paper's 256-channel network\) \| ([\d.]+ s) \| step"),
    ("train.step.landmark.cpu", "gegnn/training/estimate.py", r"one thread; [\d.]+ s against ([\d.]+ s) on a"),
    ("train.step.paper256.cpu", "gegnn/training/estimate.py", r"one thread; ([\d.]+ s) against [\d.]+ s on a"),
    ("mre.category.shipped", "docs/own-data.md", r"\| shipped `landmark` \| ([\d.]+%) \|"),
    ("mre.category.finetuned", "docs/own-data.md", r"\| fine-tuned from it, one epoch on the other shapes \| \*\*([\d.]+%)\*\* \|"),
    ("mre.category.shipped.precise", "docs/own-data.md", r"\| shipped `landmark`, no fine-tune \| ([\d.]+%) \|"),
    ("mre.category.finetuned.ft-e1-lr-0.0-decoder-warmup-1000", "docs/own-data.md",
     r"\| `--lr 0 --decoder-warmup 1000` \(the decoder alone[^|]*\| ([\d.]+%) \|"),
    ("mre.category.finetuned.ft-e2-lr-2e-05-decoder-warmup-1000", "docs/own-data.md",
     r"\| `--lr 2e-5 --decoder-warmup 1000 --epochs 2` \| ([\d.]+%) \|"),
    ("mre.category.finetuned.ft-e3-lr-3e-05", "docs/own-data.md", r"\| `--lr 3e-5 --epochs 3` \| ([\d.]+%) \|"),
    # the viewer's page
    ("page.landmark-v2.5k", "docs/queries.md", r"K = 256\): \*\*([\d.]+ MiB)\*\* at 4,762 vertices"),
    ("page.landmark-v2.50k", "docs/queries.md", r"at 4,762 vertices, ([\d.]+ MiB) at\s+50k"),
    ("page.landmark-v2.5k", "gegnn/cli/pictures.py", r"K = 256: ([\d.]+ MiB)\s+at 4,762 vertices"),
]

# What a page must no longer say: a shipped model described with another model's numbers.
STALE = [
    ("docs/queries.md", r"ships (?:three|four|five) GeGnn models"),
    ("docs/index.md", r"the (?:three|four|five) shipped models"),
    ("README.md", r"pretrained\(\"points\"\)[^\n]*3\.6[12]%"),
    ("docs/queries.md", r"5\.5 MB at 5k vertices"),
    ("docs/model-card.md", r"## `gegnn-points-v1`: point clouds \(`\"points\"`\)"),
    ("docs/model-card.md", r"## `gegnn-points-v2`: point clouds \(`\"points\"`\)"),
    ("README.md", r"pretrained\(\"points\"\)[^\n]*3\.5[01]%"),
    ("gegnn/cli/pictures.py", r"5 MB at 5k vertices"),
    # the heat-method fields' bound is landmark-v2's, not a row of the default's table
    ("README.md", r"\| the landmark lower bound alone \(256 heat-method fields\) \|"),
    ("docs/queries.md", r"\| the landmark lower bound alone \(256 heat-method fields\) \|"),
    ("docs/index.md", r"\| the landmark lower bound alone \(256 heat-method fields\) \|"),
]

WORDS = {4: "four", 5: "five", 6: "six", 7: "seven", 8: "eight", 9: "nine"}


def figures():
    return json.loads(RESULTS.read_text())["figures"]


def mismatches(claims, figures_, read):
    """Every claim whose page does not state its figure as the results file does: (key, page, what)."""
    bad = []
    for key, page, pattern in claims:
        found = re.findall(pattern, read(page))
        if not found:
            bad.append((key, page, "the sentence is gone: tie the page to docs/results.json again"))
        bad += [(key, page, f"states {value}, docs/results.json {figures_[key]['value']}")
                for value in found if value != figures_[key]["value"]]
    return bad


def read_page(page):
    """The page as a reader sees it: its marks of figures of docs/results.json gone, the figures in place."""
    return results_hook.render((ROOT / page).read_text(encoding="utf-8"))


def test_results_file_names_command_date_and_cpu():
    figs = figures()
    assert {key for key, _, _ in CLAIMS} <= set(figs)
    for key, fig in figs.items():
        for field in ("value", "what", "command", "date", "cpu", "source"):
            assert fig.get(field), f"{key}: no {field}"
        assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", fig["date"]), key
        page = fig["source"].split("#")[0]
        assert (ROOT / page).is_file(), f"{key}: {page} does not exist"


@pytest.mark.parametrize("key,page,pattern", CLAIMS, ids=[f"{k}@{p}" for k, p, _ in CLAIMS])
def test_page_states_the_figure_of_the_results_file(key, page, pattern):
    assert mismatches([(key, page, pattern)], figures(), read_page) == []


def test_a_differing_figure_is_caught():
    """The check fails on a page that states a figure otherwise, or no longer states it."""
    figs = figures()
    claim = CLAIMS[0]
    text = read_page(claim[1])
    changed = text.replace(f"**{figs[claim[0]]['value']}**", "**1.15%**")
    assert changed != text
    assert mismatches([claim], figs, lambda page: changed)[0][2].startswith("states 1.15%")
    assert "gone" in mismatches([claim], figs, lambda page: "")[0][2]


@pytest.mark.parametrize("page,pattern", STALE, ids=[f"{p}:{s[:24]}" for p, s in STALE])
def test_no_page_keeps_a_stale_figure(page, pattern):
    assert not re.search(pattern, read_page(page)), f"{page} still says {pattern!r}"


def test_pages_count_the_shipped_models():
    from gegnn.model import PRETRAINED

    weights = sorted(p.name for p in (ROOT / "gegnn" / "weights").glob("*.safetensors"))
    assert sorted(PRETRAINED.values()) == weights
    word = WORDS[len(PRETRAINED)]
    assert f"ships {word} GeGnn models" in read_page("README.md")
    assert f"ships {word} GeGnn models" in read_page("docs/queries.md")
    assert f"the {word} shipped models" in read_page("docs/index.md")
    card = read_page("docs/model-card.md")
    for name in PRETRAINED:
        assert f'`"{name}"`' in card, f"the model card has no row for {name!r}"


def test_a_benchmark_records_a_figure_with_its_command_date_and_cpu(tmp_path, monkeypatch):
    """benchmarks/results.py record: the figure's value, this command line, today's date and this CPU replace
    the old ones; the other figures stay as they were; a new figure must say what it is and where."""
    import datetime
    import sys

    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    from results import record

    path = tmp_path / "results.json"
    path.write_text(RESULTS.read_text())
    monkeypatch.setattr(sys, "argv", ["benchmarks/bench_queries.py", "data/val.zarr", "--record"])
    record("speedup.landmark-v2", "99.9x", path=path)
    before, after = figures(), json.loads(path.read_text())["figures"]
    entry = after["speedup.landmark-v2"]
    assert entry["value"] == "99.9x" and entry["date"] == datetime.date.today().isoformat()
    assert entry["command"] == "python benchmarks/bench_queries.py data/val.zarr --record"
    assert entry["cpu"] and entry["what"] == before["speedup.landmark-v2"]["what"] and "note" not in entry
    assert list(after) == list(before) and all(after[k] == before[k] for k in before if k != "speedup.landmark-v2")
    with pytest.raises(ValueError, match="new figure"):
        record("mre.landmark-v9", "0.5%", path=path)


def test_every_marked_figure_is_the_results_file_s_and_no_placeholder_is_left():
    """The pages state each figure of docs/results.json in place, between marks naming its key, so a forge, an
    editor and the site all show the value (``{{ results.KEY }}`` placeholders showed as such everywhere but the
    site): every mark names a figure of the file and states its value; a page out of step is found, named, and
    rewritten by the writer; mkdocs runs the same check."""
    assert re.search(r"(?m)^hooks:\n  - docs/_ext/results_hook\.py$", (ROOT / "mkdocs.yml").read_text())
    figs = figures()
    used = set()
    for page in results_hook.pages(ROOT):
        text = page.read_text(encoding="utf-8")
        assert "{{ results." not in text and "{{results." not in text, f"{page}: a placeholder left"
        used |= {key for key, _ in results_hook.MARKED.findall(text)}
        assert results_hook.stale(text, figs) == [], page
        assert "<!-- results" not in results_hook.render(text) and "<!-- /results" not in results_hook.render(text)
    assert used and used <= set(figs)
    page = "at <!-- results.mre.landmark-v3 -->9.99%<!-- /results -->, <!-- results.time.paper -->1 s<!-- /results -->."
    assert results_hook.stale(page, figs) == [(1, "mre.landmark-v3", "9.99%", figs["mre.landmark-v3"]["value"]),
                                              (1, "time.paper", "1 s", figs["time.paper"]["value"])]
    written = results_hook.write(page, figs)
    assert results_hook.stale(written, figs) == []
    assert results_hook.render(written) == f"at {figs['mre.landmark-v3']['value']}, {figs['time.paper']['value']}."
    with pytest.raises(KeyError, match="mre.landmark-v9"):
        results_hook.write("<!-- results.mre.landmark-v9 -->1%<!-- /results -->", figs)


def test_a_figure_changed_in_the_results_file_is_written_into_every_page_that_states_it(tmp_path):
    """results_hook.write_pages, as ``python docs/_ext/results_hook.py`` and a benchmark's --record run it: a new
    value in the file goes into each page that marks the figure, and only there."""
    import shutil

    (tmp_path / "docs").mkdir()
    for page in results_hook.pages(ROOT):
        shutil.copy(page, tmp_path / page.relative_to(ROOT))
    data = json.loads(RESULTS.read_text())
    data["figures"]["mre.landmark-v4"]["value"] = "0.01%"
    results = tmp_path / "docs" / "results.json"
    results.write_text(json.dumps(data))
    before = {p.name: p.read_text() for p in results_hook.pages(tmp_path)}
    assert results_hook.stale(before["index.md"], data["figures"])  # out of step until written
    changed = results_hook.write_pages(tmp_path, results)
    marks = [p for p in results_hook.pages(ROOT) if "<!-- results.mre.landmark-v4 -->" in p.read_text()]
    assert sorted(changed) == sorted(str(p.relative_to(ROOT)) for p in marks) and "docs/index.md" in changed
    for page in results_hook.pages(tmp_path):
        assert results_hook.stale(page.read_text(), data["figures"]) == []
    assert "**0.01%**" in results_hook.render((tmp_path / "docs" / "index.md").read_text())


def test_the_estimates_for_1k_to_50k_meshes_follow_from_the_measured_costs():
    """docs/own-data.md's table of times: each term is N meshes' prepare and fields at one mesh a core, and N / 4
    steps (the CPU's one-thread step, the GPU step of gegnn.training.estimate), from the figures of
    docs/results.json as rounded on the page; a figure measured again must change the table with it."""
    from gegnn.training.estimate import GPU_STEP_S

    figs = {k: float(v["value"].split()[0]) for k, v in figures().items() if v["value"].endswith(" s")}
    seconds = {"s": 1, "min": 60, "h": 3600}
    rows = re.findall(r"(?m)^\| ([\d,]+) \| ([^|]+) \| ([^|]+) \| [^|]+ \|$", read_page("docs/own-data.md"))
    assert [int(n.replace(",", "")) for n, _, _ in rows] == [1000, 10000, 50000]
    for n, cpu, gpu in rows:
        n = int(n.replace(",", ""))
        for cell, cores, step in ((cpu, 2, figs["train.step.landmark.cpu"]), (gpu, 16, GPU_STEP_S)):
            terms = [n * figs["prepare.mesh.cpu"] / cores, n * figs["train.fields.landmark.cpu"] / cores, n / 4 * step]
            written = re.fullmatch(r"([\d.]+) (s|min|h) \+ ([\d.]+) (s|min|h) \+ ([\d.]+) (s|min|h) = "
                                   r"\*\*([\d.]+) (s|min|h)\*\*", cell.strip())
            assert written, cell
            values = written.groups()
            for (number, unit), exact in zip(zip(values[::2], values[1::2]), [*terms, sum(terms)]):
                decimals = len(number.partition(".")[2])
                assert abs(float(number) - exact / seconds[unit]) <= 0.501 * 10 ** -decimals, (n, cell, number, unit)
