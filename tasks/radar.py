"""Radar simulation of scene files into the artifact store: the ``simulate`` job's driver
:func:`simulate_scenes` (``sim2radar simulate``; the flow :mod:`sim2radar.flows.simulate` runs it
with Prefect) and its unit of work, one scene.

Per scene, :func:`simulate_scene`:

1. hashes the scene YAML and its mesh files (:func:`sim2radar.scenes.scene_digest`) into the
   ``scene_meshes`` key, and that key + the resolved radar config + seed into the
   ``radar_points`` key (:func:`storage.content_key`);
2. if both artifacts exist, does nothing else: status ``skipped`` (resume / no recompute);
3. otherwise loads the scene (clear errors for bad mesh files / unknown materials), simulates
   one frame per radar pose with :func:`sim2radar.radar.simulate_frame`, and publishes
   ``scene_meshes`` + ``radar_points`` atomically with provenance: status ``ok``;
4. optionally renders one bird's-eye-view PNG per frame (from the stored table, so cached
   scenes get pictures too).

Errors propagate (the runner records the scene as ``failed`` in the manifest and the others
finish); ``strict`` raises :class:`SceneFailures` after everything is recorded.
"""

from __future__ import annotations

import functools
import logging
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from sim2radar.configio import DEFAULT_RADAR
from sim2radar.factory.seeds import scene_file_frame_seed
from sim2radar.scenes import expand_scenes, scene_id_for
from sim2radar.storage import (
    ArtifactStore,
    content_key,
    meshes_to_table,
    radar_frames_from_table,
    radar_frames_to_table,
)
from sim2radar.tasks.common import Outcome, RunSummary, jsonable, open_store, summarize
from sim2radar.tasks.runner import Runner, RunOptions, StepRun, Units

__all__ = [
    "RADAR_POINTS_STAGE_VERSION",
    "SCENE_MESHES_STAGE_VERSION",
    "scene_keys",
    "simulate_scene",
    "render_scene_pngs",
    "failed_outcome",
    "SimulateRequest",
    "SceneFailures",
    "simulate_scenes",
]

log = logging.getLogger(__name__)

#: Bump when the radar_points output of the same inputs changes (simulator or table logic).
#: (2: the ray tracer's IF response and element patterns, TI's detection chain; scene files
#: may give each pose a speed. 3: the receiver noise drawn in two steps, channel-integrated
#: power first: a new noise stream of the same distribution. 4: the range-Doppler profile sums
#: the array's channels only.)
RADAR_POINTS_STAGE_VERSION = 4
#: Bump when scene_meshes output changes for the same files.
SCENE_MESHES_STAGE_VERSION = 1


def _load_radar(radar):
    from sim2radar.radar import load_radar_config

    return load_radar_config(radar)


def scene_keys(scene_path: str | os.PathLike, radar, seed: int = 0) -> dict[str, str]:
    """Content keys of a scene's artifacts without loading its meshes.

    Returns ``{"scene_meshes": key, "radar_points": key}``; ``radar`` is a preset name, YAML
    path or :class:`~sim2radar.radar.RadarConfig`.
    """
    from sim2radar.scenes import scene_digest

    digest = scene_digest(scene_path)
    scene_key = content_key(
        stage="scene_meshes",
        stage_version=SCENE_MESHES_STAGE_VERSION,
        inputs={"scene_files": digest},
    )
    cfg = _load_radar(radar)
    radar_key = content_key(
        stage="radar_points",
        stage_version=RADAR_POINTS_STAGE_VERSION,
        inputs={"scene": scene_key},
        config={"radar": cfg.to_dict(), "seed": int(seed)},
    )
    return {"scene_meshes": scene_key, "radar_points": radar_key, "scene_files": digest}


def simulate_scene(
    scene_path: str | os.PathLike,
    radar: Any = DEFAULT_RADAR,
    store: str | os.PathLike | ArtifactStore = "out/store",
    *,
    seed: int = 0,
    png_dir: str | os.PathLike | None = None,
    force: bool = False,
    simulate_fn: Callable | None = None,
) -> Outcome:
    """Simulate every radar pose of one scene file into the store (skip if cached).

    Parameters
    ----------
    scene_path : path — scene YAML (see :mod:`sim2radar.scenes`)
    radar : preset name, YAML path or RadarConfig
    store : store root (path / URI) or :class:`~storage.ArtifactStore`
    seed : int — run seed; per-frame seeds derive from it, the scene key and the frame index
    png_dir : path, optional — write ``<scene_id>_f<k>.png`` bird's-eye views there
    force : bool — recompute even if the artifacts exist
    simulate_fn : callable, optional — replaces :func:`sim2radar.radar.simulate_frame`
        (same signature); for tests and alternative simulators

    Returns
    -------
    Outcome with status ``ok`` or ``skipped``; ``measured``: ``n_points`` (points per frame),
    ``locations`` (stage -> where the artifact is), ``pngs`` (bird's-eye views written).

    Raises
    ------
    sim2radar.mesh.MeshFileError
        Broken scene/mesh files, unknown materials (message names the file and entry).
    """
    t_start = time.perf_counter()
    store = open_store(store)
    scene_path = Path(scene_path)
    scene_id = scene_id_for(scene_path)
    cfg = _load_radar(radar)
    keys = scene_keys(scene_path, cfg, seed)
    artifacts = {"scene_meshes": keys["scene_meshes"], "radar_points": keys["radar_points"]}
    timings: dict[str, float] = {"keys": time.perf_counter() - t_start}

    cached = not force and store.all_exist(artifacts)
    n_points: list[int]
    if cached:
        status = "skipped"
        n_points = store.read("radar_points", keys["radar_points"], columns=["n_points"]).column(
            "n_points"
        ).to_pylist()
        log.info("scene %s: cached (radar_points %s), nothing to compute", scene_id, keys["radar_points"])
    else:
        status = "ok"
        n_points = _compute(scene_path, scene_id, cfg, store, keys, seed, timings, simulate_fn)

    outcome = Outcome(scene_id, status, artifacts=artifacts, timings_s=timings,
                      source=str(scene_path), measured={
                          "n_points": n_points, "pngs": [],
                          "locations": {s: store.uri(s, key) for s, key in artifacts.items()}})
    if png_dir is not None:
        t0 = time.perf_counter()
        outcome.measured["pngs"] = render_scene_pngs(store, keys["radar_points"], png_dir, cfg,
                                                     scene_id)
        timings["png"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    return outcome


def _compute(scene_path, scene_id, cfg, store, keys, seed, timings, simulate_fn) -> list[int]:
    from sim2radar.scenes import load_scene_file, simulate_scene_poses

    t0 = time.perf_counter()
    scene = load_scene_file(scene_path)
    meshes = list(scene.meshes)
    timings["load"] = time.perf_counter() - t0
    seeds = [scene_file_frame_seed(seed, keys["scene_meshes"], k)
             for k in range(len(scene.radar_poses))]
    points, seconds, stats = simulate_scene_poses(scene, cfg, seeds, simulate_fn)
    stats = [jsonable(s) for s in stats]
    timings["simulate"] = float(sum(seconds))

    t0 = time.perf_counter()
    common = {"seed": int(seed), "extra": {"scene_id": scene_id, "source": str(scene_path)}}
    store.write(
        "scene_meshes",
        keys["scene_meshes"],
        meshes_to_table(meshes),
        stage_version=SCENE_MESHES_STAGE_VERSION,
        provenance={**common, "inputs": {"scene_files": keys["scene_files"]}},
    )
    table = radar_frames_to_table(
        scene_id=scene_id,
        radar_to_world=list(scene.radar_poses),
        points=points,
        boxes=[scene.boxes_in_radar(k) for k in range(len(scene.radar_poses))],
        box_labels=[list(scene.box_labels)] * len(scene.radar_poses),
        sim_seconds=seconds,
    )
    store.write(
        "radar_points",
        keys["radar_points"],
        table,
        stage_version=RADAR_POINTS_STAGE_VERSION,
        provenance={
            **common,
            "inputs": {"scene": keys["scene_meshes"]},
            "config": {"radar": cfg.to_dict(), "seed": int(seed)},
            "timings_s": {"load": timings["load"], "simulate": timings["simulate"]},
            "extra": {**common["extra"], "frame_stats": stats, "radar_derived": _derived(cfg)},
        },
    )
    timings["write"] = time.perf_counter() - t0
    return [len(p) for p in points]


def _derived(cfg) -> dict[str, Any]:
    derived = getattr(cfg, "derived", None)
    try:
        return jsonable(derived() if callable(derived) else (derived or {}))
    except Exception:  # noqa: BLE001 - provenance extras must never fail a run
        return {}


def render_scene_pngs(store: ArtifactStore, radar_key: str, png_dir: str | os.PathLike,
                      cfg=None, scene_id: str | None = None) -> list[str]:
    """Bird's-eye-view PNG per frame of a stored ``radar_points`` artifact
    (:func:`sim2radar.visualize.radar_frames_pngs`); returns their paths."""
    from sim2radar.visualize import radar_frames_pngs

    frames = radar_frames_from_table(store.read("radar_points", radar_key))
    return radar_frames_pngs(frames, png_dir, radar=cfg, scene_id=scene_id)


def failed_outcome(scene_path: str | os.PathLike, error: BaseException | str) -> Outcome:
    """A ``failed`` outcome for a scene whose simulation raised ``error``."""
    return Outcome.failed(scene_id_for(scene_path), error, source=str(scene_path))


class SimulateRequest(BaseModel):
    """One run of the ``simulate`` job: scene files into the store.

    Attributes
    ----------
    scenes : scene YAML files, folders (every ``*.yaml`` inside), globs, bundled scene names
        (``demo``) — :func:`sim2radar.scenes.expand_scenes`
    radar : radar preset name or YAML path
    store : artifact store root (local path or fsspec URI)
    dataset : manifest name
    seed : run seed
    png_dir : folder for bird's-eye-view PNGs (local), or None
    force : recompute even when artifacts exist
    strict : raise :class:`SceneFailures` at the end if any scene failed
    run : how many scenes at once, and where (:class:`~sim2radar.tasks.runner.RunOptions`)
    """

    model_config = ConfigDict(extra="forbid")

    scenes: list[str] = Field(min_length=1)
    radar: str = DEFAULT_RADAR
    store: str = "out/store"
    dataset: str = "default"
    seed: int = 0
    png_dir: str | None = None
    force: bool = False
    strict: bool = False
    run: RunOptions = RunOptions()


class SceneFailures(RuntimeError):
    """Raised by a ``strict`` run when at least one scene failed; ``.summary`` has the details."""

    def __init__(self, summary: dict[str, Any]) -> None:
        failed = [s for s in summary["outcomes"] if s["status"] == "failed"]
        lines = [f"{s['id']}: {s['error']}" for s in failed]
        super().__init__(f"{len(failed)} scene(s) failed:\n" + "\n".join(lines))
        self.summary = summary


def _check_unique_ids(scenes: list[str]) -> None:
    seen: dict[str, str] = {}
    for s in scenes:
        sid = scene_id_for(s)
        if sid in seen and os.path.abspath(seen[sid]) != os.path.abspath(s):
            raise ValueError(
                f"two scene files share the scene id {sid!r}: {seen[sid]} and {s}; give each a "
                "unique 'name:' in its YAML or write them to different datasets"
            )
        seen[sid] = s


def _simulate_unit(scene_path: str, run: StepRun, *, radar, store, seed, png_dir,
                   force) -> Outcome:
    return simulate_scene(scene_path, radar, store, seed=seed, png_dir=png_dir, force=force)


def simulate_scenes(request: SimulateRequest, runner: Runner) -> RunSummary:
    """The ``simulate`` job: every scene of ``request`` simulated into the store and recorded
    in the dataset manifest (a second run recomputes nothing: every scene ``skipped`` by
    content key); a broken scene (bad mesh file, unknown material) is recorded as ``failed``
    and the others finish.

    Returns
    -------
    dict — :func:`sim2radar.tasks.common.summarize`'s (``outcomes``: the scenes) + ``radar``

    Raises
    ------
    SceneFailures — ``request.strict`` and a scene failed (after every scene is recorded)
    ValueError — two scene files share a scene id
    """
    scenes = expand_scenes(request.scenes)
    _check_unique_ids(scenes)
    units = Units(job="simulate", what="scene", task="simulate-scene", items=tuple(scenes),
                  work=functools.partial(_simulate_unit, radar=request.radar,
                                         store=request.store, seed=request.seed,
                                         png_dir=request.png_dir, force=request.force),
                  failed=failed_outcome, name=scene_id_for, store=request.store,
                  dataset=request.dataset)
    outcomes = runner.run(units)
    summary = summarize(request.store, request.dataset, outcomes, radar=request.radar)
    log.info("simulate: %s into %s (dataset %s)", summary["counts"], summary["store"],
             request.dataset)
    if request.strict and summary["counts"]["failed"]:
        raise SceneFailures(summary)
    return summary

