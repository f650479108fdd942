"""The capture factory's stages as cached steps: a capture scene (one RGB view) -> depth ->
segments -> materials -> meshes + door boxes [-> fused with the scene's other views] -> radar
poses -> radar frames, each step keyed by content and skipped when its artifact exists; and the
``captures`` job's driver :func:`capture_dataset` (``sim2radar captures``; the flow
:mod:`sim2radar.flows.capture_dataset` runs it with every step a Prefect task, ``--no-prefect``
with plain calls: the same :func:`process_capture_scene` either way).

The science is in the library (:mod:`sim2radar.reconstruct.pipeline` stage functions,
:mod:`sim2radar.factory.captures`); this module holds keys, caching, store I/O and outcomes.

Artifacts per scene (keys: :func:`sim2radar.storage.reconstruction.stage_keys`): ``depth_maps``,
``segmentations``, ``material_labels``, ``scene_meshes`` + ``reconstruction`` (level frame;
the same keys ``sim2radar reconstruct``'s flow gives the same image), and one
``dataset_frames`` per radar pose. Manifest rows: one per scene (``<scene>``) and one per frame
(``<scene>_f003``).

Views. A scene with ``views/`` and ``poses.txt`` (:func:`sim2radar.factory.captures.scene_views`)
has each of its first ``reconstruction.fusion.frames`` views reconstructed by the same cached
steps (keyed by the view's own image), and its radar poses and frames use the scene fused with
them (:func:`sim2radar.reconstruct.fusion.fuse_views`, in the scene's level frame). The fusion is
not stored: it is cheap, and the frames' keys name the views' reconstructions and poses.
"""

from __future__ import annotations

import functools
import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict

from sim2radar.factory.captures import (
    CaptureScene,
    CaptureSpec,
    capture_frame,
    find_captures,
    load_capture_frame,
    radar_mount,
    read_radar_yaml,
    sample_radar_poses,
    scene_views,
)
from sim2radar.factory.seeds import frame_seed, pose_seed, scene_seed
from sim2radar.storage import content_key, meshes_from_table
from sim2radar.storage.frames import dataset_frame_to_table
from sim2radar.tasks.common import Outcome, RunSummary, failed_scene_ids, open_store
from sim2radar.tasks.dataset import (
    DATASET_STAGE_VERSION,
    _fill_frame_outcome,
    export_all,
    outcomes_from_manifest,
    read_dataset_frame,
    summarize_dataset,
)
from sim2radar.tasks.runner import Runner, RunOptions, StepRun, Units, call_step
from sim2radar.tasks.steps import FrameSource, reconstruction_steps

__all__ = [
    "CAPTURE_STAGES",
    "CAPTURE_DOMAIN",
    "CaptureRequest",
    "capture_dataset",
    "stage_table",
    "process_capture_scene",
    "capture_frame_key",
    "poses_stage",
    "simulate_stage",
]

log = logging.getLogger(__name__)

#: The steps of one scene, in order (the Prefect task of each is named after it).
CAPTURE_STAGES = ("depth", "segments", "materials", "scene", "poses", "simulate")
#: How capture exports label their domain in ``dataset.json``.
CAPTURE_DOMAIN = "simulated from RGB captures (reconstructed geometry)"


def _source(scene: CaptureScene, spec: CaptureSpec) -> tuple[FrameSource, dict[str, str]]:
    """The scene as a :class:`~sim2radar.tasks.steps.FrameSource` (reconstruction in the level frame)
    and every key of the scene: input digests + the reconstruction steps' artifact keys.

    Raises
    ------
    ValueError naming the file, field and fix: an unreadable image or intrinsics, a
    ``radar.yaml`` that does not validate (checked here, before any reconstruction step).
    """
    from sim2radar.reconstruct.pipeline import STAGE_VERSION
    from sim2radar.storage.reconstruction import frame_input_digests, stage_keys

    frame, _ = load_capture_frame(scene)
    read_radar_yaml(scene.radar)  # a bad radar.yaml fails the scene before reconstruction
    inputs = frame_input_digests(frame)
    keys = stage_keys(inputs, spec.reconstruction.to_dict(), stage_version=STAGE_VERSION)
    src = FrameSource(scene.scene_id, scene.folder, lambda: load_capture_frame(scene), inputs,
                      keys, seed=spec.seed)
    return src, {**inputs, **keys}


def _geometry(st, keys: dict) -> tuple[Any, np.ndarray, dict]:
    """The scene's radar geometry: a :class:`~sim2radar.radar.RadarScene` of its meshes, its
    door boxes (level frame) and its reconstruction record, fused with its views
    (``keys["views"]``) when it has them."""
    from sim2radar.radar import RadarScene
    from sim2radar.storage.reconstruction import read_reconstruction

    meshes = meshes_from_table(st.read("scene_meshes", keys["scene_meshes"]))
    rec = read_reconstruction(st, keys["reconstruction"])
    boxes = np.asarray(rec["door_boxes"], np.float32).reshape(-1, 7)
    if keys.get("views"):
        from sim2radar.reconstruct.fusion import EarlierView, fuse_views

        level_from_cam = np.asarray(rec["camera_to_target"], np.float64)
        views = []
        for v in keys["views"]:
            vrec = read_reconstruction(st, v["reconstruction"])
            # view level <- view camera, scene camera <- view camera, scene level <- scene camera
            current_from_view = (level_from_cam @ np.asarray(v["scene_from_view"], np.float64)
                                 @ np.linalg.inv(vrec["camera_to_target"]))
            views.append(EarlierView(meshes_from_table(st.read("scene_meshes",
                                                               v["scene_meshes"])),
                                     vrec["door_boxes"], current_from_view))
        fused = fuse_views(meshes, boxes, views, rec["intrinsics"], level_from_cam)
        meshes, boxes = fused.meshes, fused.door_boxes
        rec = {**rec, "fusion": {"views": fused.views, "triangles_added": fused.triangles_added,
                                 "boxes_added": fused.boxes_added}}
    return RadarScene(meshes), boxes, rec


def _geometry_provisional(st, keys: dict) -> dict | None:
    """The ``provisional`` record of the scene's geometry: its reconstruction's and its
    views' (materials that fell back), None when all are results."""
    from sim2radar.storage import combine_provisional

    return combine_provisional(
        [st.provisional("reconstruction", keys["reconstruction"]),
         *(st.provisional("reconstruction", v["reconstruction"]) for v in keys.get("views", ()))])


def poses_stage(scene: CaptureScene, spec: CaptureSpec, store: str, keys: dict) -> dict:
    """Radar poses of the scene in its reconstructed free space
    (:func:`sim2radar.factory.captures.sample_radar_poses`); returns ``{"poses": (F, 4, 4)
    list, "candidates", "rejected", "wanted", "seconds"}`` (deterministic, so not stored: every
    pose is kept in its frame's ``radar_to_world``)."""
    from sim2radar.factory.labels import scene_ray_caster

    t0, st = time.perf_counter(), open_store(store)
    radar_scene, _, rec = _geometry(st, keys)
    radar_yaml = read_radar_yaml(scene.radar)
    mount = radar_mount(rec["level_from_camera"], radar_yaml["radar_from_camera"])
    caster = scene_ray_caster(radar_scene)
    hfov = float(np.degrees(rec["intrinsics"].hfov_rad))
    poses, info = sample_radar_poses(mount, caster, spec.poses, hfov_deg=hfov,
                                     seed=pose_seed(spec.seed, scene_seed(keys["image"])),
                                     given=radar_yaml["poses"])
    if not len(poses):
        raise ValueError(f"{scene.folder}: none of the {info['wanted']} radar poses in "
                         f"radar.yaml lies in free space (>= {spec.poses.clearance_m} m from "
                         "every surface, in the camera's view); move them or lower "
                         "poses.clearance_m")
    if len(poses) < info["wanted"]:
        log.warning("%s: %d of %d radar poses fit in the reconstructed free space (%d of %d "
                    "candidates rejected); narrow poses.forward_m / lateral_m to get more",
                    scene.scene_id, len(poses), info["wanted"], info["rejected"],
                    info["candidates"])
    return {"poses": poses.tolist(), **info, "seconds": time.perf_counter() - t0}


def capture_frame_key(keys: dict, scene_id: str, frame_index: int, spec: CaptureSpec,
                      radar_yaml_digest: str) -> str:
    """Content key of one capture frame's ``dataset_frames`` artifact: the scene's
    reconstruction keys, its id (the frame carries it: two folders holding the same images
    are two scenes), the frame index, and everything its pose, radar and labels depend on
    (pose sampling, radar.yaml, radar, run seed, label rule) and, for a scene fused with its
    views, each view's reconstruction keys and pose."""
    inputs = {"scene_meshes": keys["scene_meshes"], "reconstruction": keys["reconstruction"],
              "radar_yaml": radar_yaml_digest}
    if keys.get("views"):
        inputs["views"] = _views_digest(keys["views"])
    return content_key(
        stage="dataset_frames", stage_version=DATASET_STAGE_VERSION,
        inputs=inputs,
        config={"source": "capture", "scene": scene_id, "frame_index": int(frame_index),
                "poses": spec.poses.model_dump(mode="json"), "radar": spec.radar.to_dict(),
                "seed": spec.seed, "class_name": spec.class_name,
                "labels": spec.labels.model_dump()},
    )


def _views_digest(views: list[dict]) -> str:
    import json

    from sim2radar.storage.keys import bytes_digest

    return bytes_digest(json.dumps(views, sort_keys=True).encode())


def _radar_yaml_digest(scene: CaptureScene) -> str:
    from pathlib import Path

    from sim2radar.storage.keys import bytes_digest

    return bytes_digest(Path(scene.radar).read_bytes()) if scene.radar else ""


def simulate_stage(scene: CaptureScene, spec: CaptureSpec, store: str, keys: dict,
                   poses: list, indices: list[int], force: bool = False) -> list[Outcome]:
    """Radar frames at ``poses`` (frame numbers ``indices``) -> ``dataset_frames``; a cached
    frame is read back (``skipped``), a failing frame is recorded ``failed`` and the others
    go on."""
    st = open_store(store)
    yaml_digest = _radar_yaml_digest(scene)
    sseed = scene_seed(keys["image"])
    radar_scene = boxes = None
    out = []
    for k, pose in zip(indices, poses, strict=True):
        fo = Outcome(f"{scene.scene_id}_f{int(k):03d}", "skipped", index=int(k))
        key = capture_frame_key(keys, scene.scene_id, k, spec, yaml_digest)
        fo.artifacts.update({"dataset_frames/reconstructed": key,
                             "reconstruction/scene_meshes": keys["scene_meshes"],
                             "reconstruction/reconstruction": keys["reconstruction"]})
        try:
            if not force and st.cached("dataset_frames", key):
                df = read_dataset_frame(st, key)
            else:
                if radar_scene is None:
                    radar_scene, boxes, _ = _geometry(st, keys)
                df = capture_frame(radar_scene, boxes, np.asarray(pose), spec,
                                   scene_id=scene.scene_id, frame_index=k,
                                   radar_seed=frame_seed(spec.seed, sseed, k), scene_seed=-1)
                provisional = _geometry_provisional(st, keys)
                if provisional:  # made from fallback materials: made again next run
                    df.stats.setdefault("reconstruction", {}).update(
                        provisional=provisional, material_fallbacks=provisional["fallbacks"])
                st.write("dataset_frames", key, dataset_frame_to_table(df),
                         stage_version=DATASET_STAGE_VERSION, provisional=provisional,
                         provenance={"inputs": {s: keys[s] for s in ("scene_meshes",
                                                                   "reconstruction")},
                                     "config": {"radar": spec.radar.to_dict(),
                                                "frame_index": int(k),
                                                "class_name": spec.class_name},
                                     "seed": spec.seed, "timings_s": dict(df.timings_s),
                                     "extra": {"frame_id": df.frame_id, "folder": scene.folder,
                                               "radar_seed": df.stats.get("radar_seed")}})
                fo.status = "ok"
            _fill_frame_outcome(fo, df)
            fo.timings_s.pop("render", None)  # nothing rendered: a captured image
            fo.measured.pop("label_match", None)  # no ground truth to match labels against
        except Exception as exc:  # noqa: BLE001 - one broken frame must not stop the rest
            log.error("%s failed: %s: %s", fo.id, type(exc).__name__, exc)
            fo.status, fo.error = "failed", f"[simulate] {type(exc).__name__}: {exc}"
            fo.artifacts.pop("dataset_frames/reconstructed")  # never written
        out.append(fo)
    return out


def _cached_frames(scene: CaptureScene, spec: CaptureSpec, store: str,
                   keys: dict) -> list[Outcome] | None:
    """Every frame of a finished scene read back, or None when one is missing."""
    st = open_store(store)
    yaml_digest = _radar_yaml_digest(scene)
    given = read_radar_yaml(scene.radar)["poses"]  # None without radar.yaml or its poses
    n = spec.poses.frames if given is None else len(given)
    frame_keys = [capture_frame_key(keys, scene.scene_id, k, spec, yaml_digest)
                  for k in range(n)]
    if not all(st.cached("dataset_frames", key) for key in frame_keys):
        return None
    return simulate_stage(scene, spec, store, keys, [None] * n, list(range(n)))


# ---------------------------------------------------------------------------------------------
# One scene
# ---------------------------------------------------------------------------------------------
def process_capture_scene(scene: CaptureScene, spec: CaptureSpec, store: str, *,
                          force: bool = False,
                          run: Callable[..., Any] = call_step) -> Outcome:
    """Make (or find cached) every artifact of one capture scene, step by step.

    ``run(stage, fn, *args)`` calls each step: the plain call by default, a Prefect task in
    :mod:`sim2radar.flows.capture_dataset` (the same function either way). A failing step marks the
    scene ``failed`` with ``[stage] Type: message`` and stops it; a failing frame is recorded
    and the others go on. Never raises for a bad scene.

    Returns
    -------
    Outcome — ``id`` is the scene id, ``timings_s`` the wall seconds of each step in this
    run, ``artifacts`` the scene's reconstruction keys, ``parts`` its frames.
    """
    t0 = time.perf_counter()
    out = Outcome(scene.scene_id, "skipped", source=scene.folder)
    current = ["inputs"]  # the step running, for the error

    def step(stage: str, fn: Callable, *args, label: str = "") -> Any:
        current[0] = stage
        return run(stage, fn, *args, label=label)

    computed = False
    try:
        src, keys = _source(scene, spec)
        out.artifacts = dict(src.keys)
        for name, res in reconstruction_steps(src, spec.reconstruction, store, step).items():
            out.timings_s[name] = res.seconds
            computed |= res.status == "ok"
        views = []
        for view, scene_from_view in scene_views(scene, spec.reconstruction.fusion.frames):
            vsrc, vkeys = _source(view, spec)
            for name, res in reconstruction_steps(vsrc, spec.reconstruction, store, step,
                                                  view.scene_id.rsplit("/", 1)[-1]).items():
                out.timings_s[name] = out.timings_s.get(name, 0.0) + res.seconds
                computed |= res.status == "ok"
            views.append({"view": view.scene_id, "scene_meshes": vkeys["scene_meshes"],
                          "reconstruction": vkeys["reconstruction"],
                          "scene_from_view": np.asarray(scene_from_view).tolist()})
        if views:
            keys = {**keys, "views": views}
            out.artifacts.update({f"views/{v['view']}": v["reconstruction"] for v in views})
        current[0] = "simulate"
        cached = None if force else _cached_frames(scene, spec, store, keys)
        if cached is not None:
            out.parts = cached
        else:
            p = step("poses", poses_stage, scene, spec, store, keys)
            out.timings_s["poses"] = p["seconds"]
            t1 = time.perf_counter()
            poses, b = p["poses"], spec.frames_per_task
            for i in range(0, len(poses), b):
                idx = list(range(i, min(i + b, len(poses))))
                out.parts += step("simulate", simulate_stage, scene, spec, store, keys,
                                   poses[i:i + b], idx, force, label=f"f{idx[0]:03d}")
            out.timings_s["simulate"] = time.perf_counter() - t1
    except Exception as exc:  # noqa: BLE001 - one broken scene must not stop the others
        log.error("%s [%s] failed: %s: %s", scene.scene_id, current[0], type(exc).__name__, exc)
        out.status, out.error = "failed", f"[{current[0]}] {type(exc).__name__}: {exc}"
    out.timings_s["total"] = time.perf_counter() - t0
    # segments whose material fell back (the scene's and its views'): its frames are provisional
    out.measured["fallbacks"] = max((int(f.measured.get("fallbacks", 0)) for f in out.parts),
                                    default=0)
    if out.status != "failed":
        computed |= any(f.status == "ok" for f in out.parts)
        n_failed = sum(f.status == "failed" for f in out.parts)
        if n_failed:
            out.status = "failed"
            out.error = f"{n_failed} of {len(out.parts)} frame(s) failed"
        else:
            out.status = "ok" if computed else "skipped"
    return out


# ---------------------------------------------------------------------------------------------
# The job
# ---------------------------------------------------------------------------------------------
class CaptureRequest(BaseModel):
    """One run of the ``captures`` job: a lab's capture folder -> a radar dataset.

    Attributes
    ----------
    captures : the capture folder (one sub-folder per scene:
        :func:`sim2radar.factory.captures.find_captures`)
    spec : radar, reconstruction, pose sampling, labels, seed, class name
        (:class:`~sim2radar.factory.captures.CaptureSpec`)
    store : artifact store root (local path or fsspec URI)
    dataset : manifest name
    export_dir : OpenPCDet export folder, or None
    force : recompute even when cached
    retry_failed : only the scenes the manifest records as failed run; the export then holds
        every frame the manifest lists
    run : how many scenes at once, and where (:class:`~sim2radar.tasks.runner.RunOptions`)
    """

    model_config = ConfigDict(extra="forbid")

    captures: str = "captures"
    spec: CaptureSpec = CaptureSpec()
    store: str = "out/store"
    dataset: str = "captures"
    export_dir: str | None = None
    force: bool = False
    retry_failed: bool = False
    run: RunOptions = RunOptions()


def stage_table(outcomes: list[Outcome]) -> list[dict[str, Any]]:
    """One row per scene: status, frames, points per frame, wall seconds per step."""
    rows = []
    for o in outcomes:
        counts = [f.measured.get("n_points", {}) for f in o.parts]
        pts = [c["reconstructed"] for c in counts if "reconstructed" in c]
        row = {"scene": o.id, "status": o.status,
               "frames": sum(f.status != "failed" for f in o.parts),
               "points_per_frame": round(sum(pts) / len(pts), 1) if pts else None}
        for stage in CAPTURE_STAGES + ("total",):
            row[f"{stage}_s"] = round(o.timings_s[stage], 3) if stage in o.timings_s else None
        row["fallbacks"] = int(o.measured.get("fallbacks", 0))
        row["error"] = o.error
        rows.append(row)
    return rows


def _scene_unit(scene: CaptureScene, run: StepRun, *, request: CaptureRequest) -> Outcome:
    return process_capture_scene(scene, request.spec, request.store, force=request.force,
                                 run=run)


def _failed_scene(scene: CaptureScene, error: BaseException | str) -> Outcome:
    return Outcome.failed(scene.scene_id, error, source=scene.folder)


def capture_dataset(request: CaptureRequest, runner: Runner) -> RunSummary:
    """The ``captures`` job: every scene of the capture folder through its steps into the
    store, the dataset manifest and (with ``export_dir``) OpenPCDet's layout; a failing scene
    is recorded ``failed`` with its stage and error and the others finish.

    Returns
    -------
    dict — :func:`sim2radar.tasks.dataset.summarize_dataset`'s (+ ``stage_table``,
    ``export``, ``wall_s``)
    """
    t0 = time.perf_counter()
    scenes = find_captures(request.captures)
    if request.retry_failed:
        failed = set(failed_scene_ids(request.store, request.dataset))
        scenes = [s for s in scenes if s.scene_id in failed]
    units = Units(job="captures", what="scene", task="capture-scene", items=tuple(scenes),
                  work=functools.partial(_scene_unit, request=request),
                  failed=_failed_scene, name=lambda s: s.scene_id,
                  store=request.store, dataset=request.dataset)
    outcomes = runner.run(units) if scenes else []
    st = open_store(request.store)
    summary = summarize_dataset(st, request.dataset, request.spec, outcomes)
    summary["unit"], summary["ground_truth"] = "scenes", False
    summary["stage_table"] = stage_table(outcomes)
    if scenes:
        runner.publish(units.job, units.dataset, "scenes", table=summary["stage_table"],
                       description=f"capture dataset {request.dataset}: scenes "
                                   f"{summary['counts']} (seconds per step in this run; "
                                   "cached steps take milliseconds)")
    if request.export_dir is not None and (scenes or not request.retry_failed):
        # a retry exports the whole dataset its manifest lists, not only the retried scenes
        exported = (outcomes_from_manifest(st, request.dataset) if request.retry_failed
                    else outcomes)
        summary["export"] = export_all(st, exported, request.export_dir, request.spec,
                                       domain=CAPTURE_DOMAIN)
    summary["wall_s"] = time.perf_counter() - t0
    return summary
