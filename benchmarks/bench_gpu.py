"""GeGnn on one device: precomputation and 1M queries against the paper's RTX 3090 figures, fp32 against
bf16, this device against the CPU, and the training step with and without torch's deterministic algorithms.

    python benchmarks/bench_gpu.py [--device cuda] [--queries 1000000] [--steps 5]

Meshes are synthetic (a 5,000-vertex torus), so no data is needed. The paper (Pang et al. 2023, Sec. 5)
gives 0.089 s of precomputation per mesh and 0.042 s per million queries at 256 channels on an RTX 3090;
`GeGnn()` is that network (random weights: timings do not depend on them). Prints Markdown: the GPU
check (scripts/gpu_check.sh) puts it in its report.
"""
from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import torch
import trimesh

from gegnn import GeGnn
from gegnn.metrics import relative_error
from gegnn.training.devices import set_deterministic
from gegnn.training.loop import train_step
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

PAPER_EMBED_S, PAPER_QUERIES_S = 0.089, 0.042  # per mesh, per 1M queries; RTX 3090, 256 channels


def torus():
    m = trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=100, minor_sections=50)
    return np.asarray(m.vertices), np.asarray(m.faces)


def sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize()


def best_of(fn, device, repeat=5):
    fn()  # warm-up: kernel selection, allocator, landmark solver
    times = []
    for _ in range(repeat):
        sync(device)
        t = time.perf_counter()
        out = fn()
        sync(device)
        times.append(time.perf_counter() - t)
    return min(times), out


def queries(emb, n, device, seed=0):
    g = torch.Generator(device).manual_seed(seed)
    i = torch.randint(emb.num_vertices, (n,), generator=g, device=device)
    j = torch.randint(emb.num_vertices, (n,), generator=g, device=device)
    return i, j


def section_speed(models, v, f, device, n):
    print(f"\n### Precomputation and {n:,} queries ({len(v)}-vertex torus)\n")
    print("| model | embed (s) | queries (s) | paper, RTX 3090: embed / 1M queries |")
    print("|---|---:|---:|---|")
    for name, model in models.items():
        model.to(device)
        embed_s, emb = best_of(lambda: model.embed(v, f), device)
        i, j = queries(emb, n, device)
        query_s, _ = best_of(lambda: emb.distance(i, j), device)
        print(f"| {name} | {embed_s:.3f} | {query_s:.3f} | {PAPER_EMBED_S} / {PAPER_QUERIES_S} s |")


def section_agreement(model, v, f, device, n):
    """fp32 against bf16 on this device, and this device against the CPU (fp32)."""
    print("\n### Agreement (shipped landmark model)\n")
    model.to(device)
    fp32, bf16 = model.embed(v, f), model.embed(v, f, precision="bf16")
    i, j = queries(fp32, n, device)
    d32 = fp32.distance(i, j)
    rel = lambda a, b: ((a - b).abs() / b.abs().clamp_min(1e-3)).mean().item()  # noqa: E731
    print(f"- bf16 network against fp32: codes differ by {((bf16.features - fp32.features).norm() / fp32.features.norm()).item():.2e} "
          f"(relative norm); distances by {rel(bf16.distance(i, j), d32):.2e} mean relative")
    if device.type != "cpu":
        cpu = GeGnn.pretrained().embed(v, f)
        d_cpu = torch.as_tensor(cpu.distance(i.cpu().numpy(), j.cpu().numpy()))
        print(f"- {device.type} against CPU, fp32: distances differ by {rel(d32.cpu(), d_cpu):.2e} mean relative, "
              f"{((d32.cpu() - d_cpu).abs() / d_cpu.clamp_min(1e-3)).max().item():.2e} at most")


def section_training(v, f, device, steps):
    """One training step of the paper network (256 channels, 4 copies of the mesh, 100k pairs each):
    default, and under torch's deterministic algorithms (gegnn train --deterministic)."""
    from gegnn.training.data import MeshGeometry, make_batch, sample_mesh
    from geodata.mesh import Mesh, unique_edges, vertex_normals
    from geodata.stages.normalize import normalize

    v = normalize(Mesh(v, f)).vertices.astype(np.float32)
    geometry = MeshGeometry(v, vertex_normals(Mesh(v, f)).astype(np.float32), unique_edges(f).astype(np.int64),
                            f.astype(np.int64))
    rng = np.random.default_rng(0)
    pairs = rng.integers(0, len(v), (100_000, 2))
    dist = np.linalg.norm(v[pairs[:, 0]] - v[pairs[:, 1]], axis=1).astype(np.float32)
    samples = [sample_mesh(geometry, pairs, dist, rng, None, True) for _ in range(4)]
    batch = make_batch(samples, ("t",) * 4, 5, 1 / 16, 3 / 16).to(device)
    print(f"\n### Training step (paper network, 256 channels, batch of 4 x {len(v)} vertices, 400k pairs)\n")
    print("| mode | step (ms) | loss after the steps |")
    print("|---|---:|---:|")
    for deterministic in (False, True):
        set_deterministic(deterministic)
        torch.manual_seed(0)
        model = GeGnn().to(device)
        opt = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.01)
        step_s, _ = best_of(lambda: train_step(model, batch, opt, 1e-4, 1.0, device), device, steps)
        with torch.no_grad():
            loss = relative_error(model(batch.hierarchy, batch.pairs), batch.distances).mean().item()
        print(f"| {'deterministic' if deterministic else 'default'} | {step_s * 1000:.0f} | {loss:.4f} |")
    set_deterministic(False)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--queries", type=int, default=1_000_000)
    ap.add_argument("--steps", type=int, default=5)
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    device = torch.device(args.device)
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else platform.processor() or platform.machine()
    print(f"## GeGnn on {name} (torch {torch.__version__}, CUDA {torch.version.cuda})")
    v, f = torus()
    landmark, paper = GeGnn.pretrained(), GeGnn.pretrained("paper")
    models = {"GeGnn() (the paper's network, 256 channels)": GeGnn().eval(),
              f"pretrained landmark ({landmark.config.channels} channels, K = {landmark.config.landmarks})": landmark,
              f"pretrained paper ({paper.config.channels} channels)": paper}
    section_speed(models, v, f, device, args.queries)
    section_agreement(GeGnn.pretrained(), v, f, device, args.queries)
    section_training(v, f, device, args.steps)


if __name__ == "__main__":
    main()
