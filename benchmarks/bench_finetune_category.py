"""Does fine-tuning from the shipped model beat it on a category it has not seen, in minutes on a CPU?

    python benchmarks/bench_finetune_category.py WORK [--variants 8] [--epochs 1] [--lr LR] [--decoder-warmup N] [--record]

The category: the furniture-like soups of `geodata examples`, with the defects of catalog meshes. Two of the six
shapes (lamp, mug) and their variants are held out for validation; the other four and their variants
(`geodata augment`) train. The recipe is docs/own-data.md's: `geodata prepare`, then
`gegnn train --model landmark` (the shipped default's preset, fine-tuned from its weights). The validation MRE of
the shipped model and of the fine-tuned one (RUN/last.safetensors: no choice of a checkpoint by the validation
meshes) over all stored pairs of the held-out meshes, mean over meshes (the model card's protocol). WORK keeps
the stores and the runs (a rerun prepares nothing twice; remove WORK/runs to train again). --lr and
--decoder-warmup override the preset's (a run of its own for each recipe). --record writes the two figures to
docs/results.json.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

from gegnn import GeGnn
from gegnn.training.loop import evaluate_store
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

HELD_OUT = ("lamp.stl", "mug.obj")


def run(*command) -> None:
    bin_dir = Path(sys.executable).parent
    subprocess.run([str(bin_dir / command[0]), *map(str, command[1:])], check=True)


def make_stores(work: Path, variants: int, pairs: int) -> tuple[Path, Path]:
    """The train and validation stores of the category (prepared once)."""
    raw = work / "raw"
    if not (raw / "val").is_dir():
        run("geodata", "examples", work / "examples")
        for f in (work / "examples").iterdir():
            target = raw / ("val" if f.name in HELD_OUT else "train")
            target.mkdir(parents=True, exist_ok=True)
            shutil.copy(f, target / f.name)
        run("geodata", "augment", raw / "train", work / "aug/train", "--variants", variants, "--jobs", 2)
        run("geodata", "augment", raw / "val", work / "aug/val", "--variants", 2, "--jobs", 2)
    stores = work / "train.zarr", work / "val.zarr"
    for split, store in zip(("train", "val"), stores):
        for folder in (raw / split, work / "aug" / split):
            run("geodata", "prepare", folder, store, "--pairs", pairs, "--jobs", 2)
    return stores


def mean_mre(model, store) -> float:
    rows = evaluate_store(model, store)
    return sum(r["mre"] for r in rows) / len(rows)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("work", type=Path)
    parser.add_argument("--variants", type=int, default=8)
    parser.add_argument("--epochs", type=int, default=1)
    parser.add_argument("--pairs", type=int, default=20_000)
    parser.add_argument("--lr", type=float, help="peak learning rate (default: the preset's, 1e-4)")
    parser.add_argument("--decoder-warmup", type=int, help="decoder-only steps first (default: the preset's, 0)")
    parser.add_argument("--record", action="store_true")
    args = parser.parse_args()
    print(cpu_description())
    train, val = make_stores(args.work, args.variants, args.pairs)
    extra = [] if args.lr is None else ["--lr", args.lr]
    extra += [] if args.decoder_warmup is None else ["--decoder-warmup", args.decoder_warmup]
    ft = args.work / "runs" / "-".join(["ft", f"e{args.epochs}", *map(str, extra)]).replace("--", "")
    t0 = time.perf_counter()
    if not (ft / "last.safetensors").exists():
        run("gegnn", "train", train, "--val", val, "--run", ft, "--model", "landmark", "--epochs", args.epochs, *extra)
    minutes = (time.perf_counter() - t0) / 60
    shipped = mean_mre(GeGnn.pretrained("landmark"), val)
    tuned = mean_mre(GeGnn.from_checkpoint(ft / "last.safetensors"), val)
    print(f"validation MRE on the held-out shapes ({', '.join(HELD_OUT)} and their variants): shipped landmark "
          f"{100 * shipped:.3f}%, fine-tuned {100 * tuned:.3f}% ({args.epochs} epoch(s), {minutes:.1f} min of "
          "training with its fields)")
    if args.record:
        from results import record

        page, what = "docs/own-data.md#does-a-fine-tune-beat-the-shipped-model", (
            "held-out shapes of the sample soups (lamp, mug and 2 variants each), all stored pairs, mean over meshes")
        record("mre.category.shipped", f"{100 * shipped:.2f}%", f"GeGnn.pretrained() on the {what}", page)
        record("mre.category.shipped.precise", f"{100 * shipped:.3f}%", f"GeGnn.pretrained() on the {what}", page)
        options = " ".join(map(str, ["--epochs", args.epochs, *extra]))
        default = not extra and args.epochs == 1  # the page's recipe; another gets a key of its own
        key = "mre.category.finetuned" + ("" if default else "." + ft.name)
        record(key, f"{100 * tuned:.2f}%" if default else f"{100 * tuned:.3f}%", f"`gegnn train --model landmark {options}` on "
               f"the other four shapes and {args.variants} variants each, last checkpoint, on the "
               f"{what}", page)


if __name__ == "__main__":
    main()
