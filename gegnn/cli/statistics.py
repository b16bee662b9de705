"""``gegnn shape-distribution``: histograms of geodesic and Euclidean distances between random points (D2)."""
from __future__ import annotations

import csv
from pathlib import Path

import click

from .inputs import _load_mesh, _load_model, _model_and_meshes, _output_suffix
from .options import DEVICE_OPTION, PRETRAINED_HELP


@click.command("shape-distribution", context_settings={"max_content_width": 100})
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False),
                metavar="[CHECKPOINT|NAME] MESH...")
@click.option("--pretrained", is_flag=True, help=PRETRAINED_HELP)
@click.option("--pairs", default=1_000_000, show_default=True, help="Random point pairs per mesh.")
@click.option("--bins", default=64, show_default=True)
@click.option("--seed", default=0, show_default=True)
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="d2.png (geodesic and Euclidean histograms), or d2.csv (the densities).")
@DEVICE_OPTION
def shape_distribution(files, pretrained, pairs, bins, seed, output, device):
    """Shape distributions (D2, Osada et al. 2002) of each MESH with predicted geodesic distances, next to
    the Euclidean ones: histograms of the distance between random surface points (of a mesh's largest
    part) over its mean. With several meshes, the L1 distance of each histogram to the first mesh's
    (0: equal, 2: disjoint).

    \b
    Examples:
      gegnn shape-distribution --pretrained horse.obj horse-bent.obj -o d2.png
      gegnn shape-distribution runs/a/best.safetensors *.obj --pairs 200000 -o d2.csv
    """
    import numpy as np

    from ..fields.exact import largest_part
    from ..queries.statistics import geodesic_and_euclidean_d2, histogram_l1

    spec, meshes = _model_and_meshes(files, pretrained, many=True)
    suffix = _output_suffix(output, (".png", ".csv"))
    model = _load_model(spec, pretrained, device)
    results = []
    for path in meshes:
        qm = _load_mesh(path, False)
        v, f = qm.mesh.vertices, qm.mesh.faces
        geo, euc = geodesic_and_euclidean_d2(model.embed(v, f).distance, v, f, pairs, seed, bins, largest_part(qm.mesh))
        results.append((Path(path).name, geo, euc))
        line = f"{Path(path).name}: mean geodesic {geo.mean:.4g}, mean Euclidean {euc.mean:.4g}"
        if len(results) > 1:
            line += (f"; L1 to {results[0][0]}: geodesic {histogram_l1(geo, results[0][1]):.3f}, "
                     f"Euclidean {histogram_l1(euc, results[0][2]):.3f}")
        click.echo(line)
    if suffix == ".csv":
        header = ["ratio_lo", "ratio_hi"] + [f"{n}:{k}" for n, *_ in results for k in ("geodesic", "euclidean")]
        columns = [geo.edges[:-1], geo.edges[1:]] + [h.density for _, *hs in results for h in hs]
        with open(output, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows(np.stack(columns, axis=1).round(6).tolist())
    elif suffix == ".png":
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
        for ax, k, title in ((axes[0], 1, "geodesic (predicted)"), (axes[1], 2, "Euclidean")):
            for r in results:
                ax.stairs(r[k].density, r[k].edges, label=r[0], lw=1.5)
            ax.set(title=title, xlabel="distance / mean distance")
        axes[0].set_ylabel("density")
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(output, dpi=100)
        plt.close(fig)
    if output:
        click.echo(f"written {output}")
