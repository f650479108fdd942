"""The ``generate`` job's driver: N procedural worlds x M frames -> dataset frames with door
boxes (on reconstructed and/or ground-truth geometry) in the store, a table of seconds per step,
and the OpenPCDet export — on any :class:`~sim2radar.tasks.runner.Runner`.

    from sim2radar.tasks.generate import GenerateRequest, generate_dataset
    from sim2radar.tasks.runner import PlainRunner
    summary = generate_dataset(GenerateRequest(spec={"frames_per_world": 2}, n_worlds=2,
                                               store="out/store", dataset="demo"),
                               PlainRunner())

One unit per world seed: :func:`sim2radar.tasks.dataset.generate_world_dataset` (render,
reconstruction steps per frame, one simulate per geometry; cached frames read back). The flow
:func:`sim2radar.flows.generate_dataset.generate_dataset` runs the same driver with Prefect
(``sim2radar generate``; the ``nightly-generate`` deployment).
"""

from __future__ import annotations

import functools
import logging
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from sim2radar.factory.spec import MAX_WORLDS, DatasetSpec
from sim2radar.storage.worlds import world_id_for
from sim2radar.tasks.common import Outcome, RunSummary, open_store
from sim2radar.tasks.dataset import (
    export_all,
    generate_world_dataset,
    outcomes_from_manifest,
    summarize_dataset,
)
from sim2radar.tasks.runner import Runner, RunOptions, StepRun, Units
from sim2radar.tasks.worlds import failed_world

__all__ = ["GenerateRequest", "DatasetFailures", "generate_dataset", "world_table"]

log = logging.getLogger(__name__)


class GenerateRequest(BaseModel):
    """One run of the ``generate`` job: worlds x frames -> dataset frames, optionally exported.

    Attributes
    ----------
    spec : the run's :class:`~sim2radar.factory.spec.DatasetSpec` (frames per world,
        geometries, radar, reconstruction, world, rig, seed, class name, ...)
    seeds : world seeds (one seed -> one world); left empty, the worlds
        ``first_seed .. first_seed + n_worlds - 1`` (a deployment's parameters say so)
    n_worlds, first_seed : the seeds' range when ``seeds`` is empty (ignored otherwise)
    store : artifact store root (local path or fsspec URI)
    dataset : manifest name
    export_dir : OpenPCDet export folder, or None
    force : recompute dataset frames even when cached
    strict : raise :class:`DatasetFailures` at the end if anything failed or fell back
    frames_by_seed : frames of particular worlds (default ``spec.frames_per_world``)
    splits : export splits, split name -> world ids (None: seeded split by world)
    export_doppler : export points with a 5th column, Doppler [m/s]
    domain : how the export labels its domain in ``dataset.json`` (None: simulated)
    export_manifest : export every frame the dataset's manifest lists, not only this run's
        worlds (``generate --retry-failed`` runs only the worlds that failed)
    run : how many worlds at once, and where (:class:`~sim2radar.tasks.runner.RunOptions`)
    """

    model_config = ConfigDict(extra="forbid")

    spec: DatasetSpec = DatasetSpec()
    seeds: list[int] = []
    n_worlds: int = Field(4, ge=1, le=MAX_WORLDS)
    first_seed: int = 0
    store: str = "out/store"
    dataset: str = "generated"
    export_dir: str | None = None
    force: bool = False
    strict: bool = False
    frames_by_seed: dict[int, int] = {}
    splits: dict[str, list[str]] | None = None
    export_doppler: bool = False
    domain: str | None = None
    export_manifest: bool = False
    run: RunOptions = RunOptions()

    @model_validator(mode="after")
    def _world_range(self) -> GenerateRequest:
        if not self.seeds:
            self.seeds = list(range(self.first_seed, self.first_seed + self.n_worlds))
        return self


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


def _world_unit(seed: int, run: StepRun, *, request: GenerateRequest) -> Outcome:
    return generate_world_dataset(seed, request.spec, request.store, force=request.force,
                                  n_frames=request.frames_by_seed.get(int(seed)), run=run)


def generate_dataset(request: GenerateRequest, runner: Runner) -> RunSummary:
    """The ``generate`` job: each world's dataset frames made (or found cached) and recorded
    in the dataset manifest, a table of seconds per step, the export; a failing world or frame
    is recorded ``failed`` and the others finish.

    Returns
    -------
    dict — :func:`summarize_dataset`'s (+ ``stage_table``, ``export`` when exported)

    Raises
    ------
    DatasetFailures — ``request.strict`` and a world failed or a material fell back (after
        everything is recorded and exported)
    """
    units = Units(job="generate", what="world", task="generate-world-dataset",
                  items=tuple(int(s) for s in request.seeds),
                  work=functools.partial(_world_unit, request=request), failed=failed_world,
                  name=world_id_for, store=request.store, dataset=request.dataset)
    outcomes = runner.run(units)
    st = open_store(request.store)
    summary = summarize_dataset(st, request.dataset, request.spec, outcomes)
    summary["stage_table"] = world_table(outcomes)
    runner.publish(units.job, units.dataset, "worlds", table=summary["stage_table"],
                   description=f"dataset {request.dataset}: worlds {summary['counts']} (seconds "
                               "per step, summed over each world's frames; cached steps take "
                               "milliseconds)")
    if request.export_dir is not None:
        exported = (outcomes_from_manifest(st, request.dataset) if request.export_manifest
                    else outcomes)
        summary["export"] = export_all(st, exported, request.export_dir, request.spec,
                                       splits=request.splits,
                                       with_doppler=request.export_doppler,
                                       domain=request.domain)
        log.info("exported to %s: %s", request.export_dir, summary["export"])
    log.info("generate: worlds %s, frames %s into %s (dataset %s)", summary["counts"],
             summary["frame_counts"], st.root, request.dataset)
    if request.strict and (summary["counts"]["failed"] or summary["fallbacks"]["segments"]):
        raise DatasetFailures(summary)
    return summary
