"""``gegnn`` command line: train, eval, query and the applications. One module per command group:
:mod:`gegnn.cli.training` (train, eval, finetune, export), ``queries`` (query), ``matrices`` (pairwise),
``pictures`` (view, texture), ``statistics`` (shape-distribution); ``options`` and ``inputs`` are shared."""
from __future__ import annotations

import click

from .matrices import pairwise
from .pictures import texture, view
from .queries import query
from .statistics import shape_distribution
from .training import evaluate, export, finetune, train

__all__ = ["main"]


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="geogegnn")
def main():
    """Learned geodesic embeddings (GeGnn): train on a geodata store, evaluate, query, and the paper's
    applications (finetune, geodesic paths, texture mapping, shape distributions).

    \b
    Typical use:
      gegnn train out/ --run runs/a --epochs 100
      gegnn eval runs/a/best.safetensors out/
      gegnn query runs/a/best.safetensors mesh.obj --source 0 -o field.ply
      gegnn query --pretrained mesh.obj --source 0 --exact -o field.png
      gegnn query --pretrained mesh.obj --source 0 --path 99 -o path.png
      gegnn query --pretrained mesh.obj --points-file points.csv -o distances.npy
      gegnn pairwise --pretrained mesh.obj -o D.npy
      gegnn finetune --pretrained mesh.obj -o tuned.safetensors
      gegnn texture --pretrained mesh.obj --center 0 -o textured.png
      gegnn view --pretrained mesh.obj -o view.html
      gegnn shape-distribution --pretrained a.obj b.obj -o d2.png
      torchrun --nproc-per-node 4 -m gegnn.cli train out/ --run-dir runs/a
    """


for command in (train, evaluate, query, view, pairwise, finetune, texture, shape_distribution, export):
    main.add_command(command)
