"""The `geodata` command line: prepare, biharmonic, info."""
from __future__ import annotations

import contextlib
import dataclasses
import logging
import sys
from collections import defaultdict
from pathlib import Path

import click
import numpy as np
from tqdm import tqdm

from geodata import store
from geodata.geodesic import BACKENDS as BACKENDS_GEODESIC
from geodata.parallel import BACKENDS, parse_shard
from geodata.progress import progress_bar

log = logging.getLogger("geodata")
library_log = logging.getLogger("geodata.library")  # libraries' warnings: the log file only, once each


class _TqdmHandler(logging.Handler):
    """Log lines that do not break the progress bar."""

    def emit(self, record):
        tqdm.write(self.format(record), file=sys.stderr)


def _max_memory(text: str, jobs: int, scheduler: str | None) -> int | None:
    """--max-memory's bytes (None: no limit)."""
    from geodata.parallel import default_max_memory, parse_memory

    if text.strip().lower() == "auto":
        return None if scheduler else default_max_memory(jobs)
    try:
        return parse_memory(text)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--max-memory") from None


def _setup_logging(log_file: str | None) -> None:
    log.handlers.clear()
    log.setLevel(logging.INFO)
    log.propagate = False
    console = _TqdmHandler()
    console.setFormatter(logging.Formatter("geodata %(levelname)s %(message)s"))
    console.addFilter(lambda record: record.name != library_log.name)
    log.addHandler(console)
    if log_file:
        Path(log_file).parent.mkdir(parents=True, exist_ok=True)
        handler = logging.FileHandler(log_file)
        handler.setFormatter(logging.Formatter("%(asctime)s geodata %(levelname)s %(message)s"))
        log.addHandler(handler)


def _shard(ctx, param, value):
    try:
        return parse_shard(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None


def _scale_options(fn):
    """--jobs/--backend/--scheduler/--shard/--log, shared by prepare and biharmonic."""
    options = [
        click.option("--jobs", "-j", default=1, show_default=True, type=click.IntRange(1),
                     help="Meshes processed at once (worker processes; with a cluster backend and no "
                          "--scheduler, the size of the local cluster)."),
        click.option("--backend", type=click.Choice(BACKENDS), default="loky", show_default=True,
                     help="joblib backend: loky (local processes), dask or ray (needs the extra)."),
        click.option("--scheduler", metavar="ADDRESS", default=None,
                     help="Address of an existing Dask scheduler or Ray cluster (default: start a local one)."),
        click.option("--shard", metavar="K/N", default=None, callback=_shard,
                     help="Process only shard K of N (0 <= K < N), e.g. a SLURM array task; "
                          "shards may write one store at once."),
        click.option("--log", "log_file", type=click.Path(dir_okay=False), default=None,
                     help="Also append the log lines to this file."),
        click.option("--max-memory", default="auto", show_default=True, metavar="SIZE",
                     help="Memory one mesh's process may use (4G, 512M; 'none': no limit); a mesh that needs "
                          "more is recorded as failed ('out of memory') and the batch goes on, instead of the "
                          "kernel killing it (SLURM would mark the whole task OUT_OF_MEMORY). auto: 90% of "
                          "this task's memory (SLURM's allocation, the cgroup's limit, or the machine's) "
                          "over --jobs; none with --scheduler (the workers' machines are not this one)."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


CHECK_OPTION = click.option(
    "--check", is_flag=True,
    help="Do no work: print this shard's counts and exit 0 when every one of its inputs is accounted for "
         "(published, a byte copy of a published one, or a recorded failure), 3 while some are pending "
         "(what a scheduler's recovery asks before releasing the next stage). Reads no input file: one the "
         "shard's ledger does not vouch for (new, or changed since its last run) is pending. --retry-failed and "
         "--rehash change how a run works, not what a check counts.")
TIMEOUT_OPTION = click.option("--timeout", default=1800.0, show_default=True,
                              help="Seconds one mesh may take before it counts as failed.")


def _read_list(ctx, param, value):
    from geodata.prepare import read_list

    return None if value is None else read_list(value)


def _list_options(fn):
    """--include/--exclude LIST: select files under RAW_DIR by relative path."""
    fn = click.option("--exclude", type=click.Path(exists=True, dir_okay=False), callback=_read_list,
                      help="Skip the files listed (paths relative to RAW_DIR, one a line, # comments).")(fn)
    return click.option("--include", type=click.Path(exists=True, dir_okay=False), callback=_read_list,
                        help="Only the files listed (same format as --exclude). The tree is then not walked (a shard "
                             "of a large catalog reads its list alone); a listed file that is missing is "
                             "recorded as failed.")(fn)


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="geogegnn")
def main():
    """Turn raw triangle meshes into exact geodesic (and biharmonic) training data in a zarr store.

    \b
    Typical use:
      geodata examples raw/            # or bring your own meshes
      geodata prepare raw/ out/ --pairs 600000 --jobs 8
      geodata biharmonic out/ --jobs 8
      geodata info out/
      geodata verify out/              # open every file: damaged, orphaned, duplicated, unaccounted
    """


@main.command()
@click.argument("raw_dir", type=click.Path(exists=True))
@click.argument("out", type=click.Path(file_okay=False))
@click.option("--pairs", default=600_000, show_default=True, type=click.IntRange(1),
              help="Exact geodesic pairs per mesh (random sources x all other vertices).")
@click.option("--target-vertices", default=5000, show_default=True, type=click.IntRange(100),
              help="Vertex count of every output mesh (within +-20%).")
@click.option("--collapse", default=0.15, show_default=True, type=click.FloatRange(0, 0.9),
              help="Fraction of edges removed by the final QEM edge collapse.")
@click.option("--seed", default=0, show_default=True, help="Seed of the pair sampling (per mesh: seed + mesh id).")
@click.option("--geodesic-backend", type=click.Choice(BACKENDS_GEODESIC), default="vtp", show_default=True,
              help="Geodesic code: exact, all equal to 1e-9: vtp (this package's solver, the fastest), "
                   "gdist (tvb-gdist) or libigl (the reference); or approximate, for meshes too large for an exact "
                   "solve of every source, each mesh recording its measured error: paths (vtp pruned within 0.03%: "
                   "every value a real path's length, never below exact, 0.005-0.05% above it on average, 1.2-4.5x "
                   "faster than vtp) or vsp (virtual source propagation, 0.1-0.3% from exact on average and a few "
                   "percent either way at a field's worst vertex, 6-8x faster than vtp at 5k vertices and linear in "
                   "the mesh). The store records it and refuses a run with another.")
@TIMEOUT_OPTION
@click.option("--points", "n_points", type=click.IntRange(2), metavar="N",
              help="Then add N surface points per mesh with exact distances between them, --pairs of them "
                   "(the data of point-cloud models: as `geodata points OUT --points N`).")
@click.option("--retry-failed", is_flag=True, help="Try again the meshes recorded under failed/.")
@click.option("--rehash", is_flag=True,
              help="Read and hash every input file again instead of trusting the ledger where a file's size, "
                   "times and inode are unchanged (after a change no file time shows: a filesystem that does "
                   "not keep ctime, a restored disk image).")
@click.option("--strict", is_flag=True, help="Exit with status 1 when any mesh of this run failed (default: 0, "
                                             "a batch that recorded its failures did its job).")
@CHECK_OPTION
@_list_options
@_scale_options
def prepare(raw_dir, out, pairs, target_vertices, collapse, seed, geodesic_backend, timeout, n_points, retry_failed,
            rehash, strict, check, include, exclude, jobs, backend, scheduler, shard, log_file, max_memory):
    """Prepare every mesh file under RAW_DIR (OBJ/OFF/PLY/STL/GLB, searched recursively) into store OUT.

    Stages: load, watertight (manifold3d), isotropic remesh (pymeshlab), QEM edge collapse,
    normalize to [-1,1], exact geodesic pairs. A mesh counts once its zip is published; a rerun
    skips published meshes and redoes the rest (and any found damaged), so a killed run loses nothing; an
    input edited since is prepared again (its old mesh becomes an orphan: `geodata info`). Bad input is recorded
    under failed/ with the stage and reason and the batch goes on; the exit status is still 0 (use
    --strict for 1). Several RAW_DIRs may be prepared into one store (same options): ids come from
    file contents.
    """
    from geodata.points_runner import PointsConfig
    from geodata.prepare import PrepareConfig
    from geodata.shard import prepare_shard

    _setup_logging(log_file)
    config = PrepareConfig(pairs, target_vertices, collapse, seed, geodesic_backend, timeout,
                           _max_memory(max_memory, jobs, scheduler))
    points = PointsConfig(n_points, pairs, seed, timeout, config.max_memory) if n_points else None
    try:
        report = prepare_shard(raw_dir, out, config, shard, include, exclude, points, retry_failed, rehash, check,
                               _runner(jobs, backend, scheduler))
    except store.StoreError as exc:
        raise click.ClickException(str(exc)) from None
    if check:
        _exit_check(f"prepare {raw_dir} -> {out}: {report.counts}", report.pending)
    failed = sum(r["status"] != "ok" for r in report.rows)
    if strict and failed:
        raise click.ClickException(f"--strict: {failed} of {len(report.rows)} meshes failed (listed above and in "
                                   f"{out}/failed)")


CHECK_PENDING = 3  # the exit status of --check while some of the shard's work is pending


def _exit_check(line: str, n_pending: int) -> None:
    """--check: print the counts and exit 0 when nothing is pending, else CHECK_PENDING."""
    click.echo(line)
    sys.exit(CHECK_PENDING if n_pending else 0)


def _runner(jobs, backend, scheduler):
    """The shard's runner (:mod:`geodata.shard`): joblib's workers, under a progress bar."""
    from geodata.shard import local_runner

    run = local_runner(jobs, backend, scheduler)

    def with_progress(fn, tasks, what):
        try:
            yield from progress_bar(run(fn, tasks, what), total=len(tasks), desc=what, unit="mesh", disable=None,
                                    dynamic_ncols=True)
        except RuntimeError as exc:  # a backend that cannot start (Dask or Ray missing, no scheduler there)
            raise click.ClickException(str(exc)) from None

    return with_progress


@main.command()
@click.argument("out", type=click.Path(exists=True))
@click.option("--pairs", default=600_000, show_default=True, type=click.IntRange(1),
              help="Biharmonic pairs per mesh (random sources x all other vertices of their component).")
@click.option("--seed", default=0, show_default=True, help="Seed of the pair sampling (per mesh: seed + mesh id).")
@TIMEOUT_OPTION
@click.option("--retry-failed", is_flag=True, help="Try again the meshes whose biharmonic step failed.")
@CHECK_OPTION
@_scale_options
def biharmonic(out, pairs, seed, timeout, retry_failed, check, **scale):
    """Add exact biharmonic distances to every published mesh (meshes/<id>.zip) of store OUT.

    Distances follow Lipman, Rustamov and Funkhouser (2010) with libigl's cotangent Laplacian and
    Voronoi mass matrix, from one sparse factorization per mesh. Written as meshes/<id>.biharmonic.zip,
    published whole; reruns skip finished meshes and redo damaged ones.
    """
    from geodata.biharmonic_runner import BiharmonicConfig, process_biharmonic

    _add_subgroup(out, "biharmonic", process_biharmonic, BiharmonicConfig(pairs, seed, timeout), retry_failed, check,
                  **scale)


def _add_subgroup(out, subgroup, process, config, retry_failed, check, jobs, backend, scheduler, shard,
                  log_file, max_memory) -> None:
    """`geodata biharmonic` and `geodata points`: :func:`geodata.shard.subgroup_shard`, printed; ``check``: the
    counts, and exit (:func:`_exit_check`)."""
    from geodata.shard import subgroup_shard

    _setup_logging(log_file)
    config = dataclasses.replace(config, max_memory=_max_memory(max_memory, jobs, scheduler))
    try:
        report = subgroup_shard(out, subgroup, process, config, shard, None, retry_failed, check,
                                _runner(jobs, backend, scheduler))
    except store.StoreError as exc:
        raise click.ClickException(str(exc)) from None
    if check:
        where = "" if shard == (0, 1) else f" (shard {shard[0]}/{shard[1]})"
        _exit_check(f"{subgroup} {out}: {report.counts()}{where}", report.pending)


@main.command()
@click.argument("out", type=click.Path(exists=True))
@click.option("--points", "n_points", default=8000, show_default=True, type=click.IntRange(2),
              help="Surface points per mesh (area-uniform, with interpolated vertex normals).")
@click.option("--pairs", default=600_000, show_default=True, type=click.IntRange(1),
              help="Exact pairs per mesh: random source points x every other point of their component.")
@click.option("--seed", default=0, show_default=True, help="Seed of the points and sources (per mesh: seed + mesh id).")
@TIMEOUT_OPTION
@click.option("--retry-failed", is_flag=True, help="Try again the meshes whose points step failed.")
@CHECK_OPTION
@_scale_options
def points(out, n_points, pairs, seed, timeout, retry_failed, check, **scale):
    """Add surface points with exact geodesic distances between them to every published mesh of store OUT
    (the data of point-cloud models).

    The points are inserted into the mesh as vertices (the same surface, refined), so the exact solver's
    distances between them are exact, and a point that falls on a vertex has that vertex's distances.
    Written as meshes/<id>.points.zip (xyz, normals, face, bary, pairs, distances), published whole; reruns
    skip finished meshes and redo damaged ones.
    """
    from geodata.points_runner import PointsConfig, process_points

    _add_subgroup(out, "points", process_points, PointsConfig(n_points, pairs, seed, timeout), retry_failed, check,
                  **scale)


@main.command()
@click.argument("raw_dir", type=click.Path(exists=True))
@click.argument("out_dir", type=click.Path(file_okay=False))
@click.option("--variants", "-k", default=2, show_default=True, type=click.IntRange(1),
              help="Variants written per input file.")
@click.option("--seed", default=0, show_default=True, help="Seed (per file: seed + content hash + variant).")
@click.option("--jobs", "-j", default=1, show_default=True, type=click.IntRange(1), help="Files at once.")
@_list_options
def augment(raw_dir, out_dir, variants, seed, jobs, include, exclude):
    """Write randomized variants of every mesh under RAW_DIR to OUT_DIR, for `geodata prepare`.

    \b
    Each variant: anisotropic scaling along a random frame, and with probability 1/2 each a bend,
    a twist, and 1-3 cuts that open holes. Made before prepare, so the variants' distances are exact.
    Output: OUT_DIR/<relative path>.aug<k>.ply; a rerun rewrites the same files.
    """
    from joblib import Parallel, delayed

    from geodata.augment import AugmentConfig, augment_file
    from geodata.prepare import discover, raw_root

    _setup_logging(None)
    cfg = AugmentConfig(variants=variants, seed=seed)
    base = raw_root(raw_dir)
    sources = discover(raw_dir, include, exclude)
    rows = []
    calls = (delayed(augment_file)(str(base / s), s, out_dir, cfg) for s in sources)
    for row in progress_bar(Parallel(n_jobs=jobs, return_as="generator")(calls), total=len(sources), desc="augment",
                            unit="file", disable=None, dynamic_ncols=True):
        rows.append(row)
        if row["status"] != "ok":
            log.warning("FAILED %s %s", row["source"], row["error"])
    ok = sum(r["status"] == "ok" for r in rows)
    log.info("summary: %d files ok, %d failed, %d variants written to %s", ok, len(rows) - ok,
             sum(len(r.get("written", [])) for r in rows), out_dir)


@main.command()
@click.argument("old", type=click.Path(exists=True, file_okay=False))
@click.argument("new", type=click.Path(file_okay=False))
def upgrade(old, new):
    """Copy store OLD of format 1 (one folder per mesh, before geogegnn 0.2.0) into NEW, of format 2 (one zip per
    mesh), keeping the mesh ids (so a training split stays the same). Resumable; OLD is left as it is.

    Format-1 meshes have no input/ arrays (where each input vertex lies on the stored mesh): prepare the
    inputs again into a new store for those."""
    from geodata.upgrade import upgrade_store

    _setup_logging(None)
    try:
        counts = upgrade_store(old, new, lambda items: progress_bar(items, desc="upgrade", unit="mesh", disable=None))
    except store.StoreError as exc:
        raise click.ClickException(str(exc)) from None
    log.info("upgrade %s -> %s: %d meshes copied, %d already there, %d incomplete (not copied), %d failure records",
             old, new, counts["meshes"], counts["skipped"], counts["incomplete"], counts["failures"])


@main.command()
@click.argument("out_dir", type=click.Path(file_okay=False))
def examples(out_dir):
    """Write a few furniture-like triangle soups (table, chair, lamp, shelf, mug, open crate) to OUT_DIR.

    They are built from primitives with the defects of real catalog meshes, to try the pipeline on.
    """
    from geodata.examples import write_examples

    for path in write_examples(out_dir):
        click.echo(path)


@main.command()
@click.argument("out", type=click.Path(exists=True))
@click.option("--csv", "csv_file", type=click.Path(dir_okay=False, allow_dash=True), default=None,
              help="Also write one row per input file: source, sha256, mesh_id, fate (ok, duplicate, failed, "
                   "pending, damaged), detail (the mesh it duplicates, the failed stage and reason...); and one "
                   "per orphan (fate orphan: a mesh no input maps to any more); '-': the table alone, on stdout.")
def info(out, csv_file):
    """Inputs and their fates, counts, failures, sizes and stage timings of store OUT.

    Every input file any `geodata prepare` run found is accounted for: ok (its mesh), duplicate (a byte copy
    of another input's mesh), failed (stage and reason), damaged (its mesh's zip cannot be read: a rerun
    redoes it) or pending (not done yet: a run is at work, or was killed). A published mesh no input maps to
    any more (its file was edited or removed) is an orphan, left out of training. `geodata verify` checks
    every file."""
    from geodata.accounting import REMOVE_ORPHANS, fates, orphan_rows, orphans, read_attrs
    from geodata.shard import stage_seconds

    try:
        root = store.open_store(out)
    except store.StoreError as exc:
        raise click.ClickException(str(exc)) from None
    meshes = store.list_meshes(out)
    failures = store.list_failures(out)
    damaged: dict[str, str] = {}
    attrs = read_attrs(out, meshes, damaged)
    unreadable: dict[str, str] = {}
    ledgers = store.read_ledgers(out, unreadable)
    inputs = fates(ledgers, meshes, attrs, failures, damaged)
    orphaned = orphans(ledgers, meshes, unreadable)
    if csv_file == "-":  # the table alone, for a pipe
        _write_csv(csv_file, inputs + orphan_rows(orphaned, attrs))
        return
    by_fate = defaultdict(int)
    for row in inputs:
        by_fate[row["fate"]] += 1
    subs = {sub: sum(sub in s for s in meshes.values()) for sub in store.SUBGROUPS}
    sub_failed = {sub: sum(name.endswith(f".{sub}") for name in failures) for sub in store.SUBGROUPS}
    mesh_failures = {k: a for k, a in failures.items() if not k.endswith(tuple(f".{s}" for s in store.SUBGROUPS))}
    click.echo(f"store {out}  (format {root.attrs['geodata_format']}, params {root.attrs.get('params')})")
    click.echo(f"inputs: {len(inputs)} files: {by_fate['ok']} ok, {by_fate['duplicate']} duplicate, "
               f"{by_fate['failed']} failed, {by_fate['pending']} pending"
               + (f", {by_fate['damaged']} damaged" if by_fate["damaged"] else ""))
    click.echo(f"meshes: {len(meshes)} published" + (f" ({len(orphaned)} orphan)" if orphaned else "")
               + f", {len(mesh_failures)} failed; "
               + ", ".join(f"{sub}: {subs[sub]} ok, {sub_failed[sub]} failed" for sub in store.SUBGROUPS))
    counted = [a for a in attrs.values() if "n_vertices" in a and "n_pairs" in a]
    if counted:
        nv = np.array([a["n_vertices"] for a in counted])
        npairs = np.array([a["n_pairs"] for a in counted])
        click.echo(f"vertices per mesh: min {nv.min()}, mean {nv.mean():.0f}, max {nv.max()}; "
                   f"geodesic pairs: {npairs.sum():,} in all")
        click.echo(stage_seconds([a.get("timings", {}) for a in counted]))
    click.echo(f"size on disk: {_du(out) / 2**20:.1f} MiB")
    leftovers = store.temporary_files(out)
    if leftovers:
        click.echo(f"temporary files in meshes/: {len(leftovers)} (writers at work, or killed runs' leftovers: "
                   f"safe to delete while no run writes this store)")
    for name, reason in unreadable.items():
        click.echo(f"damaged ledger: sources/{name}.json  {reason} (orphans cannot be told until the prepare run "
                   f"that wrote it runs again: `geodata verify` says more)")
    for mesh_id in orphaned:
        click.echo(f"orphan: {mesh_id}  {attrs.get(mesh_id, {}).get('source', '?')}  (no input maps to it any more: "
                   f"left out of training; `{REMOVE_ORPHANS.replace('OUT', str(out))}` deletes it)")
    for mesh_id, reason in sorted(damaged.items()):
        click.echo(f"damaged: {mesh_id}  {reason} (readers raise DamagedMeshError on it; a rerun of geodata prepare "
                   f"redoes it)")
    noted = {a.get("source"): a["warnings"] for a in attrs.values() if a.get("warnings")}
    if noted:
        click.echo("ok, with warnings:")
        for source, notes in sorted(noted.items()):
            click.echo(f"  {source}  " + "; ".join(notes))
    if failures:
        click.echo("failed:")
        for name, a in sorted(failures.items(), key=lambda kv: (kv[1].get("source", ""), kv[0])):
            sub = next((f" ({s})" for s in store.SUBGROUPS if name.endswith(f".{s}")), "")
            click.echo(f"  {a.get('source')}{sub}  [{a.get('stage')}]  {a.get('error')}")
    if csv_file:
        _write_csv(csv_file, inputs + orphan_rows(orphaned, attrs))


@main.command()
@click.argument("out", type=click.Path(exists=True, file_okay=False))
@click.option("--remove-orphans", is_flag=True,
              help="Delete the orphans found (meshes no input maps to any more, with their subgroups).")
@click.option("--remove-damaged", is_flag=True,
              help="Delete the damaged zips and failure records found, for a rerun of their stage to redo them.")
def verify(out, remove_orphans, remove_damaged):
    """The store doctor: open every published zip (every member's CRC) and every ledger of store OUT and name
    each damaged, orphaned, duplicated or unaccounted entry with what to do; exit 1 when any is left.

    \b
    damaged      a zip that cannot be read whole, a ledger or failure record that cannot be read
    orphan       a published mesh no input maps to any more (its file was edited or removed)
    duplicated   one input (name and sha256) published under two ids
    unaccounted  an input neither published nor failed; a file of meshes/ that belongs to no mesh

    The --remove options delete while no run writes the store; run them only then."""
    from geodata import doctor

    try:
        findings = doctor.examine(out, lambda items: progress_bar(items, desc="verify", unit="zip", disable=None))
    except store.StoreError as exc:
        raise click.ClickException(str(exc)) from None
    removed = (doctor.remove_orphans(out, findings) if remove_orphans else []) + \
        (doctor.remove_damaged(out, findings) if remove_damaged else [])
    for name in removed:
        click.echo(f"removed: {name}")
    if removed:
        findings = doctor.examine(out)
    for finding in findings:
        click.echo(finding.line().replace(" OUT", f" {out}"))
    leftovers = store.temporary_files(out)
    if leftovers:
        click.echo(f"note: {len(leftovers)} temporary files in meshes/ (writers at work, or killed runs' leftovers: "
                   f"safe to delete while no run writes this store)")
    click.echo(f"verify {out}: {doctor.summary(findings)}")
    if findings:
        sys.exit(1)


def _write_csv(path: str, rows: list[dict]) -> None:
    import csv

    with contextlib.nullcontext(sys.stdout) if path == "-" else open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, ["source", "sha256", "mesh_id", "fate", "detail"])
        writer.writeheader()
        writer.writerows(rows)


def _du(path) -> int:
    p = Path(path)
    return sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) if p.is_dir() else 0


if __name__ == "__main__":
    main()
