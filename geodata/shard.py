"""One shard's work as a function a scheduler or a test can call: `geodata prepare`'s (plan, ledger, check, run,
points, summary) in :func:`prepare_shard`, a later stage's (biharmonic, points) in :func:`subgroup_shard`. The
command line parses options, calls these and prints; what is done, and in which order, is decided here.

A run's per-mesh work goes through a ``run(fn, tasks, what) -> rows`` callable (:func:`local_runner`: joblib's
processes, Dask or Ray; the CLI wraps it in a progress bar); each row is logged on the ``geodata`` logger as it
arrives.
"""
from __future__ import annotations

import logging
from collections import defaultdict
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from geodata import store
from geodata.parallel import in_shard, parallel_map
from geodata.prepare import PrepareConfig, ShardPlan, plan_shard, process_task
from geodata.subgroup import pending

__all__ = ["Runner", "local_runner", "StageReport", "ShardReport", "prepare_shard", "subgroup_shard",
           "stage_seconds"]

log = logging.getLogger("geodata")
library_log = logging.getLogger("geodata.library")  # libraries' warnings: the log file only, once each

Runner = Callable[[Callable, list, str], Iterable[dict]]  # (fn, tasks, what) -> one summary row per task


def local_runner(jobs: int = 1, backend: str = "loky", scheduler: str | None = None) -> Runner:
    """``fn`` over the tasks with ``jobs`` workers of ``backend`` (:func:`geodata.parallel.parallel_map`)."""
    return lambda fn, tasks, what: parallel_map(fn, tasks, jobs, backend, scheduler)


@dataclass
class StageReport:
    """A later stage's state on one shard (biharmonic, points): done, failed and pending when it was looked at (a
    check's answer; for a run, before it), and the rows of its run (none for a check)."""

    what: str
    done: int
    failed: int
    pending: int
    rows: list[dict] = field(default_factory=list)

    def counts(self) -> str:
        return f"{self.done} done, {self.failed} failed, {self.pending} pending"


@dataclass
class ShardReport:
    """A prepare shard's state (its plan, its counts in one line), the work left (a check's answer, 0: done; after
    a run 0: each task published or its failure recorded) and its run's rows (meshes, then points)."""

    plan: ShardPlan
    counts: str
    pending: int
    rows: list[dict] = field(default_factory=list)
    points: StageReport | None = None


def _where(shard: tuple[int, int]) -> str:
    return "" if shard == (0, 1) else f" (shard {shard[0]}/{shard[1]})"


def _open_store(out, config: PrepareConfig, check: bool) -> None:
    try:
        if not check:
            store.create_store(out, config.store_params())
        elif Path(out).exists():  # (no store yet: every input is pending)
            store.open_store(out)
    except OSError as exc:  # a parent that is a file, no permission, a full disk...
        raise store.StoreError(f"{out}: cannot create the store: {exc.strerror or exc}") from None


def _counts(plan: ShardPlan, shard: tuple[int, int]) -> str:
    notes = [f"{len(plan.unread)} not read yet"] * bool(plan.unread) + \
        [f"{len(plan.damaged)} damaged: redone by a run"] * bool(plan.damaged)
    return (f"{len(plan.ledger['inputs']) + len(plan.unread)} input files, {len(plan.tasks)} distinct, "
            f"{len(plan.published)} published, {len(plan.failed - plan.published)} failed, "
            f"{len(plan.pending()) + len(plan.unread)} pending" + (f" ({'; '.join(notes)})" if notes else "")
            + _where(shard))


def prepare_shard(raw_dir, out, config: PrepareConfig, shard: tuple[int, int] = (0, 1), include: set | None = None,
                  exclude: set | None = None, points=None, retry_failed: bool = False, rehash: bool = False,
                  check: bool = False, run: Runner | None = None) -> ShardReport:
    """Shard ``shard`` of a prepare of RAW_DIR into store OUT: its plan (:func:`geodata.prepare.plan_shard`), its
    ledger published before any work, its damaged meshes removed, its pending meshes prepared through ``run``
    (default :func:`local_runner`), then with ``points`` (a :class:`geodata.points_runner.PointsConfig`) the
    points of the meshes this shard prepared. ``check``: nothing is written and no input file is read; the
    report says what a run of these options leaves to do (``retry_failed`` and ``rehash`` change how a run works,
    not when it is done). StoreError where OUT cannot be opened or created."""
    _open_store(out, config, check)
    plan = plan_shard(raw_dir, out, shard, include, exclude, rehash and not check, read=not check)
    counts = _counts(plan, shard)
    shard_meshes = {t.mesh_id for t in plan.tasks}.__contains__  # the points step's: the meshes of this shard
    if check:
        report = ShardReport(plan, counts, len(plan.pending()) + len(plan.unread))
        if points is not None:
            report.points = subgroup_shard(out, "points", None, points, shard, shard_meshes, check=True) \
                if Path(out).exists() else StageReport("points", 0, 0, 0)
            report.counts += f"; points: {report.points.counts()}"
            report.pending += report.points.pending
        return report
    store.write_ledger(out, plan.ledger_name, plan.ledger)  # every input accounted for before any work
    for mesh_id, reason in plan.damaged.items():
        if store.remove_damaged(out, mesh_id):
            log.warning("damaged %s (%s): removed, to be prepared again", mesh_id, reason)
    tasks = plan.pending(retry_failed)
    log.info("prepare %s -> %s: %s; %d to do", raw_dir, out, counts, len(tasks))
    rows = _run_logged(run or local_runner(), partial(process_task, out=out, config=config), tasks, "prepare")
    log_summary(rows, len(plan.published), 0 if retry_failed else len(plan.failed - plan.published))
    report = ShardReport(plan, counts, 0, rows)
    if points is not None:
        from geodata.points_runner import process_points

        report.points = subgroup_shard(out, "points", process_points, points, shard, shard_meshes, retry_failed,
                                       run=run)
        report.rows = rows + report.points.rows
    return report


def subgroup_shard(out, subgroup: str, process, config, shard: tuple[int, int] = (0, 1), keep=None,
                   retry_failed: bool = False, check: bool = False, run: Runner | None = None) -> StageReport:
    """``process`` (e.g. :func:`geodata.biharmonic_runner.process_biharmonic`) on the shard's published meshes
    still without ``subgroup``, through ``run``; the shard's meshes are those whose id is ``in_shard``, or those
    ``keep`` accepts (prepare's points step: the meshes its shard prepared). ``check``: the counts alone, a
    recorded failure accounted for with or without ``retry_failed``. StoreError where OUT is not a store."""
    store.open_store(out)
    tasks, n_done, n_failed = pending(out, subgroup, keep or partial(in_shard, shard=shard), retry_failed and not check)
    report = StageReport(subgroup, n_done, n_failed, len(tasks))
    if check:
        return report
    log.info("%s %s: %d to do, %d already done, %d failed before%s", subgroup, out, len(tasks), n_done, n_failed,
             _where(shard))
    report.rows = _run_logged(run or local_runner(), partial(process, out=out, config=config), tasks, subgroup)
    log_summary(report.rows, n_done, n_failed)
    return report


def _run_logged(run: Runner, fn, tasks: list, what: str) -> list[dict]:
    """The rows of ``run(fn, tasks, what)``, each logged as it arrives (a library's warning once, on the log file's
    logger)."""
    rows, warned = [], set()
    for row in run(fn, tasks, what):
        rows.append(row)
        for text in row.get("warnings", []):
            if text not in warned:
                warned.add(text)
                library_log.info("library warning (first seen on %s): %s", row["source"], text)
        if row["status"] == "ok":
            log.info("ok %s %s %.1fs", row["mesh_id"], row["source"], row["seconds"])
            for note in row.get("notes", []):
                log.warning("note %s %s: %s", row["mesh_id"], row["source"], note)
        else:
            log.warning("FAILED %s %s [%s] %s", row["mesh_id"], row["source"], row["stage"], row["error"])
    return rows


def stage_seconds(timings: list[dict]) -> str:
    """One line of mean / max seconds per stage over meshes' {stage: seconds} dicts."""
    by_stage = defaultdict(list)
    for t in timings:
        for stage, seconds in t.items():
            by_stage[stage].append(seconds)
    return "seconds per mesh by stage (mean / max): " + ", ".join(
        f"{s} {np.mean(v):.2f}/{np.max(v):.2f}" for s, v in by_stage.items())


def log_summary(rows: list[dict], n_done: int, n_failed: int) -> None:
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    log.info("summary: %d ok, %d failed this run; %d committed and %d failed before", len(ok), len(failed), n_done,
             n_failed)
    if ok:
        log.info(stage_seconds([r["timings"] for r in ok]))
    for r in failed:
        log.info("  failed %s [%s] %s", r["source"], r["stage"], r["error"])
