"""The capture factory's stages as cached steps: a capture scene (one RGB view) -> depth ->
segments -> materials -> meshes + door boxes -> radar poses -> radar frames, each step keyed by
content and skipped when its artifact exists. :mod:`flows.capture_dataset` runs every step as
a Prefect task; ``--no-prefect`` runs the same :func:`process_capture_scene` with plain calls.

The science is in the library (:mod:`sim2radar.reconstruct.pipeline` stage functions,
:mod:`sim2radar.factory.captures`); this module holds keys, caching, store I/O and outcomes.

Artifacts per scene (keys: :func:`storage.reconstruction.stage_keys`): ``depth_maps``,
``segmentations``, ``material_labels``, ``scene_meshes`` + ``reconstruction`` (level frame;
the same keys ``sim2radar reconstruct``'s flow gives the same image), and one
``dataset_frames`` per radar pose. Manifest rows: one per scene (``<scene>``) and one per frame
(``<scene>_f003``).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from sim2radar.factory.captures import (
    CaptureScene,
    CaptureSpec,
    capture_frame,
    load_capture_frame,
    radar_mount,
    read_radar_yaml,
    sample_radar_poses,
)
from sim2radar.factory.seeds import frame_seed, pose_seed, scene_seed
from storage import content_key, meshes_from_table
from storage.frames import dataset_frame_to_table
from tasks.common import open_store
from tasks.dataset import (
    DATASET_STAGE_VERSION,
    FrameOutcome,
    WorldDatasetOutcome,
    _fill_frame_outcome,
    read_dataset_frame,
)

__all__ = [
    "CAPTURE_STAGES",
    "StageResult",
    "process_capture_scene",
    "capture_frame_key",
    "depth_stage",
    "segments_stage",
    "materials_stage",
    "scene_stage",
    "poses_stage",
    "simulate_stage",
]

log = logging.getLogger(__name__)

#: The steps of one scene, in order (the Prefect task of each is named after it).
CAPTURE_STAGES = ("depth", "segments", "materials", "scene", "poses", "simulate")


@dataclasses.dataclass
class StageResult:
    """What one step did: ``status`` ``ok`` (computed) or ``skipped`` (cached), its artifact
    key, wall seconds in this run and the stage's compute seconds (stored with the artifact)."""

    stage: str
    status: str
    key: str = ""
    seconds: float = 0.0
    compute_s: float = 0.0


# ---------------------------------------------------------------------------------------------
# Helpers: one frame's inputs and backends
# ---------------------------------------------------------------------------------------------
_BACKENDS = threading.local()


def _backends(config) -> tuple:
    """The (depth, segments, materials) backends of ``config``, built once per thread (model
    files load once; the built-in segmenter keeps per-call state, so threads do not share)."""
    from sim2radar.reconstruct import build_backends

    cache = getattr(_BACKENDS, "cache", None)
    if cache is None:
        cache = _BACKENDS.cache = {}
    key = repr(config.to_dict())
    if key not in cache:
        cache[key] = build_backends(config)
    return cache[key]


def _frame(scene: CaptureScene, spec: CaptureSpec):
    frame, note = load_capture_frame(scene)
    if not spec.reconstruction.rig_calibration:
        frame = frame.without_rig_calibration()
    return frame, note


def _keys(scene: CaptureScene, spec: CaptureSpec) -> tuple[dict[str, str], dict[str, str], str]:
    """(input digests, artifact keys of every reconstruction stage, note) of a scene."""
    from sim2radar.reconstruct.pipeline import STAGE_VERSION
    from storage.reconstruction import frame_input_digests, stage_keys

    frame, note = load_capture_frame(scene)
    inputs = frame_input_digests(frame)
    return inputs, stage_keys(inputs, spec.reconstruction.to_dict(),
                              stage_version=STAGE_VERSION), note


def _write(st, stage: str, key: str, table, scene: CaptureScene, spec: CaptureSpec,
           inputs: dict, seconds: float) -> None:
    from sim2radar.reconstruct.pipeline import STAGE_VERSION

    st.write(stage, key, table, stage_version=STAGE_VERSION,
             provenance={"inputs": inputs, "config": spec.reconstruction.to_dict(),
                         "seed": spec.seed, "timings_s": {stage: seconds},
                         "extra": {"scene": scene.scene_id, "folder": scene.folder}})


# ---------------------------------------------------------------------------------------------
# The steps (plain functions; flows/capture_dataset.py wraps each in a Prefect task)
# ---------------------------------------------------------------------------------------------
def depth_stage(scene: CaptureScene, spec: CaptureSpec, store: str, keys: dict) -> StageResult:
    """Stage 1, metric depth -> ``depth_maps``."""
    from sim2radar.reconstruct.pipeline import estimate_depth
    from storage.reconstruction import depth_from_table, depth_to_table

    t0, st, key = time.perf_counter(), open_store(store), keys["depth_maps"]
    if st.exists("depth_maps", key):
        _, compute_s = depth_from_table(st.read("depth_maps", key))
        return StageResult("depth", "skipped", key, time.perf_counter() - t0, compute_s)
    frame, _ = _frame(scene, spec)
    depth = estimate_depth(frame, spec.reconstruction, _backends(spec.reconstruction)[0])
    seconds = time.perf_counter() - t0
    _write(st, "depth_maps", key, depth_to_table(scene.scene_id, depth, seconds), scene, spec,
           {"image": keys.get("image", "")}, seconds)
    return StageResult("depth", "ok", key, time.perf_counter() - t0, seconds)


def segments_stage(scene: CaptureScene, spec: CaptureSpec, store: str, keys: dict) -> StageResult:
    """Stage 2, segments with semantic labels -> ``segmentations``."""
    from sim2radar.reconstruct.pipeline import segment_image
    from storage.reconstruction import depth_from_table, segments_from_table, segments_to_table

    t0, st, key = time.perf_counter(), open_store(store), keys["segmentations"]
    if st.exists("segmentations", key):
        _, compute_s = segments_from_table(st.read("segmentations", key))
        return StageResult("segments", "skipped", key, time.perf_counter() - t0, compute_s)
    frame, _ = _frame(scene, spec)
    depth, _ = depth_from_table(st.read("depth_maps", keys["depth_maps"]))
    t1 = time.perf_counter()
    seg = segment_image(frame, depth, _backends(spec.reconstruction)[1])
    seconds = time.perf_counter() - t1
    _write(st, "segmentations", key, segments_to_table(scene.scene_id, seg, seconds), scene, spec,
           {"depth_maps": keys["depth_maps"]}, seconds)
    return StageResult("segments", "ok", key, time.perf_counter() - t0, seconds)


def materials_stage(scene: CaptureScene, spec: CaptureSpec, store: str,
                    keys: dict) -> StageResult:
    """Stage 3, a material per segment (the VLM's or the prior's) -> ``material_labels``."""
    from sim2radar.reconstruct.pipeline import label_materials
    from storage.reconstruction import (
        depth_from_table,
        materials_from_table,
        materials_to_table,
        segments_from_table,
    )

    t0, st, key = time.perf_counter(), open_store(store), keys["material_labels"]
    if st.exists("material_labels", key):
        _, _, compute_s = materials_from_table(st.read("material_labels", key))
        return StageResult("materials", "skipped", key, time.perf_counter() - t0, compute_s)
    frame, _ = _frame(scene, spec)
    depth, _ = depth_from_table(st.read("depth_maps", keys["depth_maps"]))
    seg, _ = segments_from_table(st.read("segmentations", keys["segmentations"]))
    t1 = time.perf_counter()
    labels, fallbacks = label_materials(frame, depth, seg, spec.reconstruction,
                                        _backends(spec.reconstruction)[2])
    seconds = time.perf_counter() - t1
    _write(st, "material_labels", key,
           materials_to_table(scene.scene_id, labels, fallbacks, seconds), scene, spec,
           {"segmentations": keys["segmentations"]}, seconds)
    return StageResult("materials", "ok", key, time.perf_counter() - t0, seconds)


def scene_stage(scene: CaptureScene, spec: CaptureSpec, store: str, keys: dict) -> StageResult:
    """Stage 4, meshes + door boxes in the level frame -> ``scene_meshes`` + ``reconstruction``."""
    from sim2radar.reconstruct.pipeline import STAGE_VERSION, build_scene
    from storage.reconstruction import (
        depth_from_table,
        materials_from_table,
        read_reconstruction,
        segments_from_table,
        write_scene_artifacts,
    )

    t0, st = time.perf_counter(), open_store(store)
    key = keys["reconstruction"]
    if st.exists("reconstruction", key) and st.exists("scene_meshes", keys["scene_meshes"]):
        compute_s = float(read_reconstruction(st, key)["timings_s"].get("total", 0.0))
        return StageResult("scene", "skipped", key, time.perf_counter() - t0, compute_s)
    frame, note = _frame(scene, spec)
    depth, t_depth = depth_from_table(st.read("depth_maps", keys["depth_maps"]))
    seg, t_seg = segments_from_table(st.read("segmentations", keys["segmentations"]))
    labels, fallbacks, t_mat = materials_from_table(st.read("material_labels",
                                                            keys["material_labels"]))
    t1 = time.perf_counter()
    rec = build_scene(frame, depth, seg, labels, spec.reconstruction,
                      timings_s={"depth": t_depth, "segments": t_seg, "materials": t_mat},
                      fallbacks=fallbacks + ([note] if note else []))
    seconds = time.perf_counter() - t1
    rec.timings_s["total"] = t_depth + t_seg + t_mat + seconds
    if not rec.meshes:
        raise ValueError(f"{scene.folder}: the reconstruction has no meshes; nothing for the "
                         "radar (check the image and the depth: LiDAR in view?)")
    write_scene_artifacts(st, rec, inputs={k: keys[k] for k in ("image", "intrinsics")},
                          config=spec.reconstruction.to_dict(), seed=spec.seed,
                          stage_version=STAGE_VERSION)
    return StageResult("scene", "ok", key, time.perf_counter() - t0, seconds)


def _radar_scene(st, keys: dict):
    from sim2radar.radar import RadarScene

    return RadarScene(meshes_from_table(st.read("scene_meshes", keys["scene_meshes"])))


def poses_stage(scene: CaptureScene, spec: CaptureSpec, store: str, keys: dict) -> dict:
    """Radar poses of the scene in its reconstructed free space
    (:func:`sim2radar.factory.captures.sample_radar_poses`); returns ``{"poses": (F, 4, 4)
    list, "candidates", "rejected", "wanted", "seconds"}`` (deterministic, so not stored: every
    pose is kept in its frame's ``radar_to_world``)."""
    from sim2radar.factory.labels import scene_ray_caster
    from storage.reconstruction import read_reconstruction

    t0, st = time.perf_counter(), open_store(store)
    rec = read_reconstruction(st, keys["reconstruction"])
    radar_yaml = read_radar_yaml(scene.radar)
    mount = radar_mount(rec["level_from_camera"], radar_yaml["radar_from_camera"])
    caster = scene_ray_caster(_radar_scene(st, keys))
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
    (pose sampling, radar.yaml, radar, run seed, label rule)."""
    return content_key(
        stage="dataset_frames", stage_version=DATASET_STAGE_VERSION,
        inputs={"scene_meshes": keys["scene_meshes"], "reconstruction": keys["reconstruction"],
                "radar_yaml": radar_yaml_digest},
        config={"source": "capture", "scene": scene_id, "frame_index": int(frame_index),
                "poses": spec.poses.model_dump(mode="json"), "radar": spec.radar.to_dict(),
                "seed": spec.seed, "class_name": spec.class_name,
                "labels": spec.labels.model_dump()},
    )


def _radar_yaml_digest(scene: CaptureScene) -> str:
    from pathlib import Path

    from storage.keys import bytes_digest

    return bytes_digest(Path(scene.radar).read_bytes()) if scene.radar else ""


def simulate_stage(scene: CaptureScene, spec: CaptureSpec, store: str, keys: dict,
                   poses: list, indices: list[int], force: bool = False) -> list[FrameOutcome]:
    """Radar frames at ``poses`` (frame numbers ``indices``) -> ``dataset_frames``; a cached
    frame is read back (``skipped``), a failing frame is recorded ``failed`` and the others
    go on."""
    from storage.reconstruction import read_reconstruction

    st = open_store(store)
    yaml_digest = _radar_yaml_digest(scene)
    sseed = scene_seed(keys["image"])
    radar_scene = rec = None
    out = []
    for k, pose in zip(indices, poses, strict=True):
        fo = FrameOutcome(f"{scene.scene_id}_f{int(k):03d}", scene.scene_id, -1, int(k),
                          "skipped")
        key = capture_frame_key(keys, scene.scene_id, k, spec, yaml_digest)
        fo.artifacts.update({"dataset_frames/reconstructed": key,
                             "reconstruction/scene_meshes": keys["scene_meshes"],
                             "reconstruction/reconstruction": keys["reconstruction"]})
        try:
            if not force and st.exists("dataset_frames", key):
                df = read_dataset_frame(st, key)
            else:
                if radar_scene is None:
                    radar_scene = _radar_scene(st, keys)
                    rec = read_reconstruction(st, keys["reconstruction"])
                df = capture_frame(radar_scene, rec["door_boxes"], np.asarray(pose), spec,
                                   scene_id=scene.scene_id, frame_index=k,
                                   radar_seed=frame_seed(spec.seed, sseed, k), scene_seed=-1)
                st.write("dataset_frames", key, dataset_frame_to_table(df),
                         stage_version=DATASET_STAGE_VERSION,
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
            fo.label_match.clear()  # no ground truth to match labels against
        except Exception as exc:  # noqa: BLE001 - one broken frame must not stop the rest
            log.error("%s failed: %s: %s", fo.frame_id, type(exc).__name__, exc)
            fo.status, fo.error = "failed", f"[simulate] {type(exc).__name__}: {exc}"
        out.append(fo)
    return out


def _cached_frames(scene: CaptureScene, spec: CaptureSpec, store: str,
                   keys: dict) -> list[FrameOutcome] | None:
    """Every frame of a finished scene read back, or None when one is missing."""
    st = open_store(store)
    yaml_digest = _radar_yaml_digest(scene)
    n = spec.poses.frames if scene.radar is None or read_radar_yaml(scene.radar)["poses"] is None \
        else len(read_radar_yaml(scene.radar)["poses"])
    frame_keys = [capture_frame_key(keys, scene.scene_id, k, spec, yaml_digest)
                  for k in range(n)]
    if not all(st.exists("dataset_frames", key) for key in frame_keys):
        return None
    return simulate_stage(scene, spec, store, keys, [None] * n, list(range(n)))


# ---------------------------------------------------------------------------------------------
# One scene
# ---------------------------------------------------------------------------------------------
def _call(stage: str, fn: Callable, *args) -> Any:
    return fn(*args)


def process_capture_scene(scene: CaptureScene, spec: CaptureSpec, store: str, *,
                          force: bool = False,
                          run: Callable[..., Any] = _call) -> WorldDatasetOutcome:
    """Make (or find cached) every artifact of one capture scene, step by step.

    ``run(stage, fn, *args)`` calls each step: the plain call by default, a Prefect task in
    :mod:`flows.capture_dataset` (the same function either way). A failing step marks the
    scene ``failed`` with ``[stage] Type: message`` and stops it; a failing frame is recorded
    and the others go on. Never raises for a bad scene.

    Returns
    -------
    WorldDatasetOutcome — ``world_id`` is the scene id, ``timings_s`` the wall seconds of each
    step in this run, ``artifacts`` the scene's reconstruction keys.
    """
    t0 = time.perf_counter()
    out = WorldDatasetOutcome(scene.scene_id, -1, "skipped", source=scene.folder)
    stage = "inputs"
    computed = False
    try:
        inputs, keys, _ = _keys(scene, spec)
        keys = {**inputs, **keys}
        out.artifacts = {s: keys[s] for s in ("depth_maps", "segmentations", "material_labels",
                                              "scene_meshes", "reconstruction")}
        for stage, fn in (("depth", depth_stage), ("segments", segments_stage),
                          ("materials", materials_stage), ("scene", scene_stage)):
            res = run(stage, fn, scene, spec, store, keys)
            out.timings_s[stage] = res.seconds
            computed |= res.status == "ok"
        stage = "simulate"
        cached = None if force else _cached_frames(scene, spec, store, keys)
        if cached is not None:
            out.frames = cached
        else:
            stage = "poses"
            p = run("poses", poses_stage, scene, spec, store, keys)
            out.timings_s["poses"] = p["seconds"]
            stage = "simulate"
            t1 = time.perf_counter()
            poses, b = p["poses"], spec.frames_per_task
            for i in range(0, len(poses), b):
                idx = list(range(i, min(i + b, len(poses))))
                out.frames += run("simulate", simulate_stage, scene, spec, store, keys,
                                  poses[i:i + b], idx, force)
            out.timings_s["simulate"] = time.perf_counter() - t1
    except Exception as exc:  # noqa: BLE001 - one broken scene must not stop the others
        log.error("%s [%s] failed: %s: %s", scene.scene_id, stage, type(exc).__name__, exc)
        out.status, out.error = "failed", f"[{stage}] {type(exc).__name__}: {exc}"
    out.timings_s["total"] = time.perf_counter() - t0
    if out.status != "failed":
        computed |= any(f.status == "ok" for f in out.frames)
        n_failed = sum(f.status == "failed" for f in out.frames)
        if n_failed:
            out.status = "failed"
            out.error = f"{n_failed} of {len(out.frames)} frame(s) failed"
        else:
            out.status = "ok" if computed else "skipped"
    return out
