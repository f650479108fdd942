"""Flow: a lab's RGB capture folder -> a radar dataset, one scene at a time, stage by stage.

    from sim2radar.flows.capture_dataset import capture_dataset
    summary = capture_dataset("captures/", store="out/store", dataset="lab",
                              export_dir="out/openpcdet")

Per scene (one RGB view) a ``capture-scene`` task runs :func:`sim2radar.tasks.capture.process_capture_scene`
with every step as its own Prefect task (``depth``, ``segments``, ``materials``, ``scene``,
``poses``, ``simulate`` per batch of ``frames_per_task`` radar poses), so the UI shows per scene
which stage ran, was **Cached** (its artifact existed: the task ends in a ``Cached`` state), was
retried or failed, and how long it took. Only ``materials`` is retried (backoff 2 s, 8 s) and
only on network errors (the VLM server); deterministic and local-I/O failures fail at once.
Manifest writes are retried (remote stores). The run publishes a progress artifact that moves
as scenes finish and a table artifact (scenes ok/failed/skipped, frames, points per frame,
seconds per stage).

A failing scene is recorded ``failed`` with its stage and error and the others finish; a
second run recomputes nothing. Scenes run one at a time by default (Mitsuba uses every core);
``workers > 1`` uses threads, ``dask_address`` a Dask cluster (:func:`sim2radar.flows.runners.task_runner`).
"""

from __future__ import annotations

import os
import time
from typing import Any

from prefect import flow, task
from prefect.cache_policies import NO_CACHE

from sim2radar.configio import DEFAULT_RADAR
from sim2radar.factory.captures import CaptureScene, CaptureSpec, find_captures
from sim2radar.flows import _progress
from sim2radar.flows._states import finish, relay, run_flow
from sim2radar.flows._steps import gather, run_as_tasks
from sim2radar.flows.runners import ThreadRunner
from sim2radar.storage import ArtifactStore
from sim2radar.tasks import capture as steps
from sim2radar.tasks.common import Outcome, run_plain
from sim2radar.tasks.dataset import export_all, summarize_dataset

__all__ = ["capture_dataset_flow", "capture_dataset", "capture_dataset_job", "progress_callback",
           "CAPTURE_DOMAIN", "stage_table"]

#: How capture exports label their domain in ``dataset.json``.
CAPTURE_DOMAIN = "simulated from RGB captures (reconstructed geometry)"


def _simulate_batch_name(stage: str, args: tuple) -> str:
    return f"-f{args[5][0]:03d}" if stage == "simulate" else ""


@task(name="capture-scene", cache_policy=NO_CACHE, retries=0, persist_result=False)
def capture_scene_task(scene: CaptureScene, spec: CaptureSpec, store: str,
                       force: bool = False) -> Outcome:
    """One scene, every step a Prefect task (:func:`sim2radar.tasks.capture.process_capture_scene`)."""
    return steps.process_capture_scene(scene, spec, store, force=force,
                                       run=run_as_tasks(scene.scene_id, _simulate_batch_name))


def progress_callback(fn):
    """Context manager: call ``fn(outcome)`` in this process after each scene finishes."""
    return _progress.listen("capture_dataset", fn)


def stage_table(outcomes: list[Outcome]) -> list[dict[str, Any]]:
    """One row per scene: status, frames, points per frame, wall seconds per step."""
    rows = []
    for o in outcomes:
        counts = [f.measured.get("n_points", {}) for f in o.parts]
        pts = [c["reconstructed"] for c in counts if "reconstructed" in c]
        row = {"scene": o.id, "status": o.status,
               "frames": sum(f.status != "failed" for f in o.parts),
               "points_per_frame": round(sum(pts) / len(pts), 1) if pts else None}
        for stage in steps.CAPTURE_STAGES + ("total",):
            row[f"{stage}_s"] = round(o.timings_s[stage], 3) if stage in o.timings_s else None
        row["fallbacks"] = int(o.measured.get("fallbacks", 0))
        row["error"] = o.error
        rows.append(row)
    return rows


@flow(name="capture-dataset", task_runner=ThreadRunner(max_workers=1), log_prints=False)
def capture_dataset_flow(
    scenes: list[CaptureScene],
    spec: CaptureSpec,
    store: str = "out/store",
    dataset: str = "captures",
    export_dir: str | None = None,
    force: bool = False,
) -> dict[str, Any]:
    """Every capture scene through its steps into the store, the ``dataset`` manifest and
    (with ``export_dir``) OpenPCDet's layout.

    Returns
    -------
    dict — :func:`sim2radar.tasks.dataset.summarize_dataset` (+ ``export``, ``stage_table``)
    """
    from prefect.artifacts import create_progress_artifact, create_table_artifact

    st = ArtifactStore(store)
    st.manifest(dataset)  # validates the name before any work
    progress_id = create_progress_artifact(
        progress=0.0, key=_progress.artifact_key("captures", dataset, "progress"),
        description=f"capture dataset {dataset}: scenes finished of {len(scenes)}")
    futures = {capture_scene_task.with_options(task_run_name=f"scene-{s.scene_id}").submit(
        s, spec, store, force): i for i, s in enumerate(scenes)}
    outcomes = gather(
        futures, lambda i, error: Outcome.failed(scenes[i].scene_id, error,
                                                       source=scenes[i].folder),
        store=store, dataset=dataset, progress_id=progress_id, channel="capture_dataset")
    summary = _finish(st, dataset, spec, [outcomes[i] for i in range(len(scenes))], export_dir)
    create_table_artifact(
        table=summary["stage_table"], key=_progress.artifact_key("captures", dataset, "scenes"),
        description=f"capture dataset {dataset}: scenes {summary['counts']} (seconds per step "
                    "in this run; cached steps take milliseconds)")
    return finish(summary, failed=summary["counts"]["failed"], total=len(scenes),
                  unit="scenes")


def _finish(st, dataset: str, spec: CaptureSpec, outcomes: list[Outcome],
            export_dir: str | None) -> dict[str, Any]:
    summary = summarize_dataset(st, dataset, spec, outcomes)
    summary["unit"], summary["ground_truth"] = "scenes", False
    summary["stage_table"] = stage_table(outcomes)
    if export_dir is not None:
        summary["export"] = export_all(st, outcomes, export_dir, spec, domain=CAPTURE_DOMAIN)
    return summary


def capture_dataset_plain(scenes: list[CaptureScene], spec: CaptureSpec, store: str,
                          dataset: str = "captures", *, export_dir: str | None = None,
                          force: bool = False, on_scene=None) -> dict[str, Any]:
    """The flow's semantics without the Prefect engine (``--no-prefect``, notebooks): the same
    :func:`sim2radar.tasks.capture.process_capture_scene` per scene, with plain calls."""
    st = ArtifactStore(store)
    # process_capture_scene records a broken scene in its outcome and never raises
    outcomes = run_plain(scenes, lambda s: steps.process_capture_scene(s, spec, store,
                                                                       force=force),
                         lambda s, error: Outcome.failed(s.scene_id, error,
                                                               source=s.folder),
                         st, dataset, on_scene)
    return _finish(st, dataset, spec, outcomes, export_dir)


def capture_dataset(
    captures: str | os.PathLike,
    store: str | os.PathLike = "out/store",
    dataset: str = "captures",
    *,
    export_dir: str | os.PathLike | None = None,
    force: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
    use_prefect: bool = True,
    on_scene=None,
    retry_failed: bool = False,
    **spec_fields: Any,
) -> dict[str, Any]:
    """Run the capture flow (or its plain loop) on every scene of a capture folder.

    ``spec_fields`` are :class:`~sim2radar.factory.captures.CaptureSpec` fields (``radar``,
    ``reconstruction``, ``poses``, ``labels``, ``seed``, ...), validated before any work.
    ``retry_failed``: only the scenes the ``dataset`` manifest records as failed run; the
    export then holds every frame the manifest lists.
    """
    from sim2radar.flows.runners import task_runner
    from sim2radar.tasks.common import failed_scene_ids

    t0 = time.perf_counter()
    spec = CaptureSpec(**spec_fields)
    scenes = find_captures(captures)
    export = None if export_dir is None else os.fspath(export_dir)
    whole_export = None
    if retry_failed:
        failed = set(failed_scene_ids(store, dataset))
        scenes = [s for s in scenes if s.scene_id in failed]
        whole_export, export = export, None
        if not scenes:
            summary = _finish(ArtifactStore(os.fspath(store)), dataset, spec, [], None)
            summary["wall_s"] = time.perf_counter() - t0
            return summary
    if not use_prefect:
        summary = capture_dataset_plain(scenes, spec, os.fspath(store), dataset,
                                        export_dir=export, force=force, on_scene=on_scene)
    else:
        runner = task_runner(workers, dask_address)
        with progress_callback(on_scene or (lambda _o: None)):
            summary = run_flow(capture_dataset_flow.with_options(task_runner=runner),
                               scenes=scenes, spec=spec, store=os.fspath(store),
                               dataset=dataset, export_dir=export, force=force)
    if whole_export is not None:
        from sim2radar.tasks.dataset import outcomes_from_manifest

        st = ArtifactStore(os.fspath(store))
        summary["export"] = export_all(st, outcomes_from_manifest(st, dataset), whole_export,
                                       spec, domain=CAPTURE_DOMAIN)
    summary["wall_s"] = time.perf_counter() - t0
    return summary


@flow(name="capture-dataset-job", log_prints=False)
def capture_dataset_job(
    captures: str = "captures",
    store: str = "out/store",
    dataset: str = "captures",
    export_dir: str | None = None,
    radar: str | dict = DEFAULT_RADAR,
    reconstruction: str | dict | None = None,
    poses: dict | None = None,
    labels: dict | None = None,
    seed: int = 0,
    class_name: str = "door",
    force: bool = False,
    retry_failed: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """Deployment entry point (``deploy/prefect.yaml``): a capture folder through
    :func:`capture_dataset` as a subflow. Parameters are JSON values: ``radar`` a preset name,
    YAML path or RadarConfig fields; ``reconstruction`` a preset name, YAML path, fields or
    None (built-in backends: the capture needs ``lidar.npy``; a YAML with ``moge`` does not);
    ``poses`` / ``labels`` fields of :class:`~sim2radar.factory.captures.PoseSampling` /
    :class:`~sim2radar.factory.labels.LabelConfig`. Relative paths resolve against the worker's
    working directory. ``retry_failed`` reruns only the scenes the manifest records as failed.
    """
    import importlib

    # run the package's copy (a deployment loads this file as a top-level module, whose
    # objects Dask workers could not import by reference): see flows/generate_dataset.py
    package = importlib.import_module("sim2radar.flows.capture_dataset")
    return relay(package.capture_dataset(
        captures, store, dataset, export_dir=export_dir, force=force, workers=workers,
        dask_address=dask_address, retry_failed=retry_failed, radar=radar,
        reconstruction=reconstruction, poses=poses or {}, labels=labels or {}, seed=seed,
        class_name=class_name), "scenes")
