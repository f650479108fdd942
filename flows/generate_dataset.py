"""Flow: the factory's nightly job — N procedural worlds x M frames -> radar frames with door
boxes (on reconstructed and/or ground-truth geometry) in the store, optionally exported to
OpenPCDet's custom layout.

    from sim2radar.flows.generate_dataset import generate_dataset
    spec = DatasetSpec(frames_per_world=8, geometry="both")   # + radar, reconstruction, ...
    summary = generate_dataset(spec, n_worlds=4, store="out/store", dataset="nightly",
                               export_dir="out/openpcdet")

One task per world seed (``generate_world_dataset_task``), its steps (render, reconstruction
steps per frame, one simulate per geometry) as nested tasks that end **Cached** when
their artifact exists (:mod:`sim2radar.flows._steps`); worlds are gathered as they complete; each
world's outcome (world row + one row per frame) goes into the dataset manifest. A second run
with the same inputs recomputes nothing (every frame ``skipped`` by content key). A failing
world or frame is recorded as ``failed`` with its error and the others finish; ``strict=True``
raises :class:`DatasetFailures` at the end (after everything is recorded and exported).

Task runner (:func:`sim2radar.flows.runners.task_runner`): worlds run one at a time by default (Mitsuba
already uses every core for one frame); ``workers > 1`` uses a thread pool; ``dask_address`` =
a Dask scheduler address (``tcp://host:8786``) or ``"local"`` (a LocalCluster of ``workers``
single-threaded processes) fans worlds out over Dask (``pip install 'sim2radar[dask]'``). A
world task receives only its seed, the :class:`~sim2radar.factory.spec.DatasetSpec` and the
store path/URI; the frames it
makes go to the store and only a small outcome comes back, so everything pickles and each
worker process selects its own Mitsuba variant.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable, Sequence
from typing import Any

from prefect import flow, get_run_logger, task
from prefect.cache_policies import NO_CACHE

from sim2radar.factory.spec import DatasetSpec, as_spec
from sim2radar.flows import _progress
from sim2radar.flows._states import finish, relay, run_flow
from sim2radar.flows._steps import gather, run_as_tasks
from sim2radar.flows.runners import ThreadRunner, task_runner
from sim2radar.storage import ArtifactStore
from sim2radar.tasks.common import Outcome
from sim2radar.tasks.dataset import (
    export_all,
    generate_world_dataset,
    summarize_dataset,
)
from sim2radar.tasks.worlds import failed_world

__all__ = ["generate_dataset_flow", "generate_dataset", "generate_dataset_job", "DatasetFailures",
           "progress_callback"]


class DatasetFailures(RuntimeError):
    """Raised by a ``strict`` run when a world or frame failed or a material fell back;
    ``.summary`` has the details."""

    def __init__(self, summary: dict[str, Any]) -> None:
        lines = []
        for w in summary["outcomes"]:
            if w["status"] != "failed":
                continue
            lines.append(f"{w['id']}: {w['error']}")
            lines += [f"  {f['id']}: {f['error']}" for f in w["parts"]
                      if f["status"] == "failed"]
        fb = (summary.get("fallbacks") or {}).get("segments", 0)
        head = f"{summary['counts']['failed']} world(s) failed"
        if fb:
            head += f", {fb} segment material(s) fell back to unknown"
        super().__init__(f"{head}:\n" + "\n".join(lines))
        self.summary = summary


def progress_callback(fn: Callable[[Outcome], None]):
    """Context manager: call ``fn(outcome)`` in this process after each world finishes."""
    return _progress.listen("generate_dataset", fn)


def world_table(outcomes: list[Outcome]) -> list[dict[str, Any]]:
    """One row per world: status, frames, radar points per frame (each geometry), seconds per
    step summed over the world's frames (render, reconstruct, simulate per geometry) and the
    world's total, the error."""
    rows = []
    for o in outcomes:
        row: dict[str, Any] = {"world": o.id, "status": o.status,
                               "frames": sum(f.status != "failed" for f in o.parts)}
        counts = [f.measured.get("n_points", {}) for f in o.parts]
        for g in sorted({g for c in counts for g in c}):
            pts = [c[g] for c in counts if g in c]
            row[f"points_per_frame_{g}"] = round(sum(pts) / len(pts), 1)
        for stage in sorted({s for f in o.parts for s in f.timings_s}):
            row[f"{stage}_s"] = round(sum(f.timings_s.get(stage, 0.0) for f in o.parts), 3)
        row["total_s"] = round(o.timings_s.get("total", 0.0), 3)
        row["fallbacks"] = int(o.measured.get("fallbacks", 0))
        row["error"] = o.error
        rows.append(row)
    return rows


def _step_name(stage: str, args: tuple) -> str:
    """Task-run name suffix of a world's step: the frame (and geometry) it works on."""
    if stage == "simulate":  # the world's frames still to compute, in one geometry
        return f"-{args[2]}"
    if stage == "render":
        return ""
    return "-" + args[0].name.rsplit("_", 1)[-1]  # a FrameSource named world_<seed>_f<k>


@task(name="generate-world-dataset", cache_policy=NO_CACHE, retries=0, persist_result=False)
def generate_world_dataset_task(seed: int, spec: DatasetSpec, store: str, force: bool = False,
                                n_frames: int | None = None) -> Outcome:
    """One world, every step a Prefect task (:func:`sim2radar.tasks.dataset.generate_world_dataset`):
    ``render``, per frame ``depth``/``segments``/``materials``/``scene`` (reconstructed, when
    not cached) and one ``simulate`` per geometry. No retries: the steps are deterministic."""
    from sim2radar.storage.worlds import world_id_for

    return generate_world_dataset(seed, spec, store, force=force, n_frames=n_frames,
                                  run=run_as_tasks(world_id_for(seed), _step_name))


@flow(name="generate-dataset", task_runner=ThreadRunner(max_workers=1), log_prints=False)
def generate_dataset_flow(
    seeds: list[int],
    spec: DatasetSpec,
    store: str = "out/store",
    dataset: str = "generated",
    export_dir: str | None = None,
    force: bool = False,
    strict: bool = False,
    frames_by_seed: dict[int, int] | None = None,
    splits: dict[str, list[str]] | None = None,
    export_doppler: bool = False,
    domain: str | None = None,
) -> dict[str, Any]:
    """Generate each world's dataset frames and record them in the ``dataset`` manifest.

    Parameters
    ----------
    seeds : world seeds (one seed -> one world)
    spec : :class:`~sim2radar.factory.spec.DatasetSpec` (frames per world, geometries, radar,
        reconstruction, world, rig, seed, class name, ...)
    store : artifact store root (local path or fsspec URI)
    dataset : manifest name
    export_dir : OpenPCDet export folder, or None
    force : recompute dataset frames even when cached
    strict : raise :class:`DatasetFailures` at the end if anything failed
    frames_by_seed : frames of particular worlds (default ``spec["frames_per_world"]``)
    splits : export splits, split name -> world ids (default: seeded split by world)
    export_doppler : export points with a 5th column, Doppler [m/s]
    domain : how the export labels its domain in ``dataset.json`` (default: simulated)

    Returns
    -------
    dict — :func:`sim2radar.tasks.dataset.summarize_dataset` (+ ``export``)
    """
    from prefect.artifacts import create_progress_artifact, create_table_artifact

    logger = get_run_logger()
    st = ArtifactStore(store)
    st.manifest(dataset)  # validates the name before any work
    progress_id = create_progress_artifact(
        progress=0.0, key=_progress.artifact_key("generate", dataset, "progress"),
        description=f"dataset {dataset}: worlds finished of {len(seeds)}")
    frames_by_seed = {int(k): int(v) for k, v in (frames_by_seed or {}).items()}
    futures = {
        generate_world_dataset_task.with_options(task_run_name=f"world-{s}").submit(
            int(s), spec, store, force, frames_by_seed.get(int(s))): int(s)
        for s in seeds
    }
    outcomes = gather(futures, failed_world, store=store, dataset=dataset,
                      progress_id=progress_id, channel="generate_dataset", what="world")
    ordered = [outcomes[int(s)] for s in seeds]
    summary = summarize_dataset(st, dataset, spec, ordered)
    summary["stage_table"] = world_table(ordered)
    create_table_artifact(
        table=summary["stage_table"], key=_progress.artifact_key("generate", dataset, "worlds"),
        description=f"dataset {dataset}: worlds {summary['counts']} (seconds per step, summed "
                    "over each world's frames; cached steps take milliseconds)")
    if export_dir is not None:
        summary["export"] = export_all(st, ordered, export_dir, spec, splits=splits,
                                       with_doppler=export_doppler, domain=domain)
        logger.info("exported to %s: %s", export_dir, summary["export"])
    logger.info("generate-dataset: worlds %s, frames %s into %s (dataset %s)",
                summary["counts"], summary["frame_counts"], st.root, dataset)
    if strict and (summary["counts"]["failed"] or summary["fallbacks"]["segments"]):
        raise DatasetFailures(summary)
    fc = summary["frame_counts"]
    return finish(summary, failed=summary["counts"]["failed"], total=len(seeds), unit="worlds",
                  detail=f" ({fc['failed']} of {sum(fc.values())} frames)")


def generate_dataset(
    spec: DatasetSpec | dict | None = None,
    n_worlds: int = 4,
    store: str | os.PathLike = "out/store",
    dataset: str = "generated",
    export_dir: str | os.PathLike | None = None,
    *,
    first_seed: int = 0,
    seeds: Sequence[int] | None = None,
    force: bool = False,
    strict: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """Run :func:`generate_dataset_flow` on worlds ``first_seed .. first_seed + n_worlds - 1``
    (or explicit ``seeds``).

    Parameters
    ----------
    spec : :class:`~sim2radar.factory.spec.DatasetSpec`, or its settings as a dict
        (``{"frames_per_world": 4, "geometry": "both", "radar": "ti-mmwcas", ...}``), validated
        here before the flow starts so a bad field fails fast with its name; None: defaults
    workers : worlds in parallel (threads, or LocalCluster processes with ``dask_address="local"``)
    dask_address : None (threads), ``"local"`` or a Dask scheduler address ``tcp://host:8786``
    """
    spec = as_spec(spec if spec is not None else {})
    seed_list = [int(s) for s in (seeds if seeds is not None
                                  else range(int(first_seed), int(first_seed) + int(n_worlds)))]
    if not seed_list:
        raise ValueError("no worlds to generate: n_worlds must be >= 1")
    runner = task_runner(workers, dask_address)
    return run_flow(generate_dataset_flow.with_options(task_runner=runner),
                    seeds=seed_list, spec=spec, store=os.fspath(store), dataset=dataset,
                    export_dir=None if export_dir is None else os.fspath(export_dir),
                    force=force, strict=strict)


@flow(name="generate-dataset-job", log_prints=False)
def generate_dataset_job(
    spec: DatasetSpec,
    n_worlds: int = 4,
    first_seed: int = 0,
    store: str = "out/store",
    dataset: str = "generated",
    export_dir: str | None = None,
    force: bool = False,
    strict: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """Deployment entry point (see ``deploy/prefect.yaml``): worlds ``first_seed ..
    first_seed + n_worlds - 1`` through :func:`generate_dataset` as a subflow on the chosen
    task runner (threads, or Dask with ``dask_address`` = scheduler address or ``"local"``).

    ``spec`` is the run's :class:`~sim2radar.factory.spec.DatasetSpec` as one parameter: its
    settings as JSON (``frames_per_world``, ``geometry``, ``radar`` a preset name, YAML path or
    RadarConfig fields, ``reconstruction`` a preset name, YAML path, fields or null for the
    built-in backends, ``world`` / ``rig`` WorldConfig / RigConfig fields, ...), validated by
    Prefect into the spec. Relative paths resolve against the worker's working directory.
    """
    # Prefect loads a deployment's entrypoint file as a top-level module ("generate_dataset");
    # objects from that copy would pickle by reference to a module Dask's scheduler and workers
    # cannot import. Run the package's copy of the flow instead (the same code).
    package = importlib.import_module("sim2radar.flows.generate_dataset")
    return relay(package.generate_dataset(
        spec, n_worlds=n_worlds, store=store, dataset=dataset, export_dir=export_dir,
        first_seed=first_seed, force=force, strict=strict, workers=workers,
        dask_address=dask_address), "worlds")
