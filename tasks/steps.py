"""The reconstruction of one RGB view as four cached steps — depth, segments, materials, scene
— shared by both sources of the factory: a capture folder's scene (:mod:`sim2radar.tasks.capture`) and a
procedural world's frame (:mod:`sim2radar.tasks.dataset`). Each step reads its inputs from the store,
runs one stage of :mod:`sim2radar.reconstruct.pipeline` and writes its artifact under its
content key (:func:`sim2radar.storage.reconstruction.stage_keys`), or returns ``skipped`` when the
artifact exists. A step runner (:data:`sim2radar.tasks.runner.StepRun`) calls each: plainly, or as a
Prefect task (:func:`sim2radar.flows.engine.run_as_tasks`).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from sim2radar.tasks.common import open_store
from sim2radar.tasks.runner import call_step

log = logging.getLogger(__name__)

__all__ = ["RECONSTRUCTION_STEPS", "FrameSource", "StageResult", "depth_stage",
           "segments_stage", "materials_stage", "scene_stage", "reconstruction_steps",
           "material_fallbacks"]

#: The reconstruction's steps, in order.
RECONSTRUCTION_STEPS = ("depth", "segments", "materials", "scene")


@dataclasses.dataclass
class StageResult:
    """What one step did: ``status`` ``ok`` (computed) or ``skipped`` (cached), its artifact
    key, wall seconds in this run and the stage's compute seconds (stored with the artifact)."""

    stage: str
    status: str
    key: str = ""
    seconds: float = 0.0
    compute_s: float = 0.0


@dataclasses.dataclass(eq=False)
class FrameSource:
    """One RGB view to reconstruct and where its reconstruction goes.

    Attributes
    ----------
    name : str — scene or frame id (artifact tables, logs).
    origin : str — where it came from (a capture folder, ``world_000003 frame 2``; provenance).
    load : callable -> (FrameInput, note) — reads the view (``note``: e.g. dropped LiDAR rows).
    inputs : dict — digests of the view's inputs, the ``inputs`` of the scene artifacts.
    keys : dict — artifact keys of every step (``depth_maps``, ``segmentations``,
        ``material_labels``, ``scene_meshes``, ``reconstruction``).
    camera_to_target : (4, 4) or None — frame of the stored meshes and boxes (None: level).
    ground_truth : the world frame, for ``oracle`` backends (None for captures).
    seed : int or None — recorded in provenance.
    """

    name: str
    origin: str
    load: Callable[[], tuple[Any, str]]
    inputs: dict[str, str]
    keys: dict[str, str]
    camera_to_target: np.ndarray | None = None
    ground_truth: Any = None
    seed: int | None = None

    def frame(self, config):
        """The view as a FrameInput (without its rig calibration when the config says so)."""
        frame, note = self.load()
        if not config.rig_calibration:
            frame = frame.without_rig_calibration()
        return frame, note


_BACKENDS: dict[str, tuple] = {}
_BACKENDS_LOCK = threading.Lock()


def _backends(config, ground_truth=None) -> tuple:
    """The (depth, segments, materials) backends of ``config``, built once per process (model
    files load once) and shared by its threads: a backend keeps no per-call state (what a call
    measures comes back in its result); ``oracle`` backends are built per view with its ground
    truth."""
    from sim2radar.reconstruct import build_backends

    if any(s.name == "oracle" for s in (config.depth, config.segments, config.materials)):
        return build_backends(config, ground_truth)
    key = repr(config.to_dict())
    with _BACKENDS_LOCK:
        if key not in _BACKENDS:
            _BACKENDS[key] = build_backends(config)
        return _BACKENDS[key]


def _write(st, stage: str, table, src: FrameSource, config, inputs: dict,
           seconds: float, provisional: dict | None = None) -> None:
    from sim2radar.reconstruct.pipeline import STAGE_VERSION

    st.write(stage, src.keys[stage], table, stage_version=STAGE_VERSION,
             provenance={"inputs": inputs, "config": config.to_dict(), "seed": src.seed,
                         "timings_s": {stage: seconds},
                         "extra": {"name": src.name, "origin": src.origin}},
             provisional=provisional)


def material_fallbacks(labels) -> dict | None:
    """The ``provisional`` record of a frame's material labels (None: every label is an
    answer): how many segments fell back to ``unknown`` (a failed VLM request, an unusable or
    out-of-vocabulary answer) and the first one's reason."""
    fell = [lab for lab in labels if getattr(lab, "fallback", False)]
    if not fell:
        return None
    return {"fallbacks": len(fell), "reason": f"{len(fell)} of {len(labels)} segment "
            f"material(s) fell back to unknown ({fell[0].reason})"}


def depth_stage(src: FrameSource, config, store: str) -> StageResult:
    """Stage 1, metric depth -> ``depth_maps``."""
    from sim2radar.reconstruct.pipeline import estimate_depth
    from sim2radar.storage.reconstruction import depth_from_table, depth_to_table

    t0, st, key = time.perf_counter(), open_store(store), src.keys["depth_maps"]
    if st.cached("depth_maps", key):
        _, compute_s = depth_from_table(st.read("depth_maps", key))
        return StageResult("depth", "skipped", key, time.perf_counter() - t0, compute_s)
    frame, _ = src.frame(config)
    depth = estimate_depth(frame, config, _backends(config, src.ground_truth)[0])
    seconds = time.perf_counter() - t0
    _write(st, "depth_maps", depth_to_table(src.name, depth, seconds), src, config,
           src.inputs, seconds)
    return StageResult("depth", "ok", key, time.perf_counter() - t0, seconds)


def segments_stage(src: FrameSource, config, store: str) -> StageResult:
    """Stage 2, segments with semantic labels -> ``segmentations``."""
    from sim2radar.reconstruct.pipeline import segment_image
    from sim2radar.storage.reconstruction import (
        depth_from_table,
        segments_from_table,
        segments_to_table,
    )

    t0, st, key = time.perf_counter(), open_store(store), src.keys["segmentations"]
    if st.cached("segmentations", key):
        _, compute_s = segments_from_table(st.read("segmentations", key))
        return StageResult("segments", "skipped", key, time.perf_counter() - t0, compute_s)
    frame, _ = src.frame(config)
    depth, _ = depth_from_table(st.read("depth_maps", src.keys["depth_maps"]))
    t1 = time.perf_counter()
    seg = segment_image(frame, depth, _backends(config, src.ground_truth)[1])
    seconds = time.perf_counter() - t1
    _write(st, "segmentations", segments_to_table(src.name, seg, seconds), src, config,
           {"depth_maps": src.keys["depth_maps"]}, seconds)
    return StageResult("segments", "ok", key, time.perf_counter() - t0, seconds)


def materials_stage(src: FrameSource, config, store: str) -> StageResult:
    """Stage 3, a material per segment (the VLM's or the prior's) -> ``material_labels``."""
    from sim2radar.reconstruct.pipeline import label_materials
    from sim2radar.storage.reconstruction import (
        depth_from_table,
        materials_from_table,
        materials_to_table,
        segments_from_table,
    )

    t0, st, key = time.perf_counter(), open_store(store), src.keys["material_labels"]
    if st.cached("material_labels", key):  # a provisional (fallback) one: ask again
        _, _, compute_s = materials_from_table(st.read("material_labels", key))
        return StageResult("materials", "skipped", key, time.perf_counter() - t0, compute_s)
    frame, _ = src.frame(config)
    depth, _ = depth_from_table(st.read("depth_maps", src.keys["depth_maps"]))
    seg, _ = segments_from_table(st.read("segmentations", src.keys["segmentations"]))
    t1 = time.perf_counter()
    labels, fallbacks = label_materials(frame, depth, seg, config,
                                        _backends(config, src.ground_truth)[2])
    seconds = time.perf_counter() - t1
    provisional = material_fallbacks(labels)
    if provisional:
        log.warning("%s: %s; stored as provisional: the next run asks again",
                    src.name, provisional["reason"])
    _write(st, "material_labels", materials_to_table(src.name, labels, fallbacks, seconds),
           src, config, {"segmentations": src.keys["segmentations"]}, seconds, provisional)
    return StageResult("materials", "ok", key, time.perf_counter() - t0, seconds)


def scene_stage(src: FrameSource, config, store: str) -> StageResult:
    """Stage 4, meshes + door boxes in ``src.camera_to_target`` -> ``scene_meshes`` +
    ``reconstruction`` (the keys :func:`sim2radar.storage.reconstruction.reconstruction_keys` gives)."""
    from sim2radar.reconstruct.pipeline import STAGE_VERSION, build_scene
    from sim2radar.storage.reconstruction import (
        depth_from_table,
        materials_from_table,
        read_reconstruction,
        segments_from_table,
        write_scene_artifacts,
    )

    t0, st = time.perf_counter(), open_store(store)
    key = src.keys["reconstruction"]
    if st.cached("reconstruction", key) and st.cached("scene_meshes", src.keys["scene_meshes"]):
        compute_s = float(read_reconstruction(st, key)["timings_s"].get("total", 0.0))
        return StageResult("scene", "skipped", key, time.perf_counter() - t0, compute_s)
    frame, note = src.frame(config)
    depth, t_depth = depth_from_table(st.read("depth_maps", src.keys["depth_maps"]))
    seg, t_seg = segments_from_table(st.read("segmentations", src.keys["segmentations"]))
    labels, fallbacks, t_mat = materials_from_table(st.read("material_labels",
                                                            src.keys["material_labels"]))
    t1 = time.perf_counter()
    rec = build_scene(frame, depth, seg, labels, config,
                      timings_s={"depth": t_depth, "segments": t_seg, "materials": t_mat},
                      fallbacks=fallbacks + ([note] if note else []))
    seconds = time.perf_counter() - t1
    rec.timings_s["total"] = t_depth + t_seg + t_mat + seconds
    written = write_scene_artifacts(st, rec, inputs=src.inputs, config=config.to_dict(),
                                    camera_to_target=src.camera_to_target, seed=src.seed,
                                    stage_version=STAGE_VERSION,
                                    provisional=st.provisional("material_labels",
                                                               src.keys["material_labels"]))
    if written["reconstruction"] != key:
        raise RuntimeError(f"{src.name}: the scene's keys {written} are not the step's "
                           f"{src.keys}; FrameSource.keys must come from stage_keys / "
                           "reconstruction_keys of the same inputs and target frame")
    return StageResult("scene", "ok", key, time.perf_counter() - t0, seconds)


def reconstruction_steps(src: FrameSource, config, store: str,
                         run: Callable[..., Any] = call_step,
                         label: str = "") -> dict[str, StageResult]:
    """Every step of one view in order through ``run(stage, fn, *args, label=label)`` (plain
    calls by default, Prefect tasks in a flow, named with ``label``: a world's frame ``f002``,
    a capture scene's view ``v1``); a failing step raises and the ones after it do not run.
    Returns stage -> StageResult."""
    out = {}
    for stage, fn in zip(RECONSTRUCTION_STEPS,
                         (depth_stage, segments_stage, materials_stage, scene_stage),
                         strict=True):
        out[stage] = run(stage, fn, src, config, store, label=label)
    return out
