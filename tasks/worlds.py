"""Procedural worlds into the artifact store: the ``worlds`` job's driver
:func:`generate_worlds` (``sim2radar worlds generate``; the flow :mod:`sim2radar.flows.worlds`
runs it with Prefect) and its unit of work, one world.

Per world seed, :func:`generate_world_artifacts`:

1. computes content keys from (seed, resolved WorldConfig, generator version) for the
   ``scene_meshes`` and ``world_specs`` artifacts, and from (those keys, resolved RigConfig,
   frame count, trajectory seed, render version) for ``world_frames``;
2. if all three exist, does nothing else: status ``skipped`` (resume / no recompute);
3. otherwise generates the world, walks the trajectory, renders every frame with Mitsuba and
   publishes the three artifacts atomically with provenance: status ``ok``.

The world's geometry is a plain ``scene_meshes`` artifact, so the radar stage can simulate it
directly; ``world_frames`` rows carry each frame's ``radar_to_world`` pose and door boxes.

With ``radar="ti-mmwcas"`` (a preset name or YAML path) each frame is also simulated by
:func:`sim2radar.radar.simulate_frame` on the world's ground-truth geometry at the frame's radar
pose, into a ``radar_points`` artifact (one row per frame) labelled with the door boxes whose
centre lies in the radar's field of view and range — a ready pre-training set.
"""

from __future__ import annotations

import functools
import logging
import os
import time

from pydantic import BaseModel, ConfigDict, Field

from sim2radar.storage import ArtifactStore, content_key, meshes_to_table
from sim2radar.storage.worlds import world_id_for
from sim2radar.tasks.common import Outcome, RunSummary, jsonable, open_store, summarize
from sim2radar.tasks.runner import Runner, RunOptions, StepRun, Units
from sim2radar.worlds.config import RigConfig, WorldConfig

__all__ = [
    "world_keys",
    "generate_world_artifacts",
    "WorldsRequest",
    "generate_worlds",
    "failed_world",
    "world_source",
]

log = logging.getLogger(__name__)

#: Version of the radar_points produced here (bump with changes to the labelling below).
RADAR_POINTS_STAGE_VERSION = 2  # 2: labels are the doors the radar sees (visibility rule)


def _configs(world_cfg, rig):
    from sim2radar.worlds.config import resolve_world_configs

    return resolve_world_configs(world_cfg, rig)


def world_keys(seed: int, n_frames: int, world_cfg=None, rig=None,
               trajectory_seed: int = 0, radar=None, *, rgb: bool = True) -> dict[str, str]:
    """Content keys ``{"scene_meshes", "world_specs", "world_frames"}`` of one world, plus
    ``"radar_points"`` when ``radar`` (preset name, YAML path or RadarConfig) is given.
    ``rgb=False``: frames without the path-traced RGB image and LiDAR (exact maps, poses and
    door boxes only: all a ground-truth-geometry radar needs), under their own key."""
    from sim2radar.worlds import RENDER_VERSION, STAGE_VERSION

    world_cfg, rig = _configs(world_cfg, rig)
    cfg = {"world": world_cfg.model_dump(mode="json"), "seed": int(seed)}
    meshes = content_key(stage="scene_meshes", stage_version=STAGE_VERSION,
                         inputs={"generator": "sim2radar.worlds"}, config=cfg)
    specs = content_key(stage="world_specs", stage_version=STAGE_VERSION, config=cfg)
    frame_cfg = {"rig": rig.model_dump(mode="json"), "n_frames": int(n_frames),
                 "trajectory_seed": int(trajectory_seed)}
    if not rgb:
        frame_cfg["rgb"] = False
    frames = content_key(
        stage="world_frames", stage_version=RENDER_VERSION,
        inputs={"scene_meshes": meshes, "world_specs": specs}, config=frame_cfg,
    )
    keys = {"scene_meshes": meshes, "world_specs": specs, "world_frames": frames}
    if radar is not None:
        from sim2radar.radar import RadarConfig, load_radar_config

        radar_cfg = radar if isinstance(radar, RadarConfig) else load_radar_config(radar)
        keys["radar_points"] = content_key(
            stage="radar_points", stage_version=RADAR_POINTS_STAGE_VERSION,
            inputs={"scene": meshes, "world_frames": frames},
            config={"radar": radar_cfg.to_dict(), "seed": int(seed)},
        )
    return keys


def generate_world_artifacts(
    seed: int,
    n_frames: int,
    store: str | os.PathLike | ArtifactStore = "out/store",
    world_cfg=None,
    rig=None,
    *,
    trajectory_seed: int = 0,
    force: bool = False,
    radar=None,
    rgb: bool = True,
) -> Outcome:
    """Generate, render and store one world (skip if its artifacts exist).

    Parameters
    ----------
    seed : int — world seed
    n_frames : int — frames along the trajectory
    store : store root (path / URI) or ArtifactStore
    world_cfg, rig : WorldConfig / RigConfig (or dicts of their fields; None = defaults)
    trajectory_seed : int
    force : bool — recompute even if cached
    radar : str or RadarConfig, optional — also simulate radar point clouds per frame
    rgb : bool — path trace RGB and cast the LiDAR (False: exact maps, poses, boxes only)

    Returns
    -------
    Outcome — ``measured``: ``n_frames``, ``doors_visible`` (visible doors per frame).
    """
    from sim2radar.storage.worlds import frames_to_table, world_id_for, world_spec_to_table
    from sim2radar.worlds import generate_world, render_frame, trajectory

    t_start = time.perf_counter()
    store = open_store(store)
    world_cfg, rig = _configs(world_cfg, rig)
    keys = world_keys(seed, n_frames, world_cfg, rig, trajectory_seed, radar, rgb=rgb)
    world_id = world_id_for(seed)
    timings: dict[str, float] = {}
    if not force and store.all_exist(keys):
        table = store.read("world_frames", keys["world_frames"], columns=["door_visible"])
        visible = [int(sum(v)) for v in table.column("door_visible").to_pylist()]
        timings["total"] = time.perf_counter() - t_start
        return _outcome(world_id, seed, "skipped", keys, timings, visible)

    t0 = time.perf_counter()
    world = generate_world(seed, world_cfg)
    timings["generate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    frames = [render_frame(world, pose, rig, rgb=rgb, lidar=rgb)
              for pose in trajectory(world, n_frames, seed=trajectory_seed)]
    timings["render"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    common = {"seed": int(seed), "extra": {"world_id": world_id, "layout": world.layout}}
    cfg = {"world": world_cfg.model_dump(mode="json"), "seed": int(seed)}
    store.write("scene_meshes", keys["scene_meshes"], meshes_to_table(world.meshes),
                stage_version=_stage_version(), provenance={**common, "config": cfg})
    store.write("world_specs", keys["world_specs"], world_spec_to_table(world),
                stage_version=_stage_version(), provenance={**common, "config": cfg})
    store.write(
        "world_frames", keys["world_frames"], frames_to_table(frames, world_id),
        stage_version=_render_version(),
        provenance={
            **common,
            "inputs": {"scene_meshes": keys["scene_meshes"], "world_specs": keys["world_specs"]},
            "config": {"rig": rig.model_dump(mode="json"), "n_frames": int(n_frames),
                       "trajectory_seed": int(trajectory_seed), "rgb": bool(rgb)},
            "timings_s": {"generate": timings["generate"], "render": timings["render"],
                          "per_frame": jsonable([f.timings_s for f in frames])},
        },
    )
    timings["write"] = time.perf_counter() - t0
    if radar is not None:
        t0 = time.perf_counter()
        _simulate_radar(world, frames, radar, store, keys, seed, world_id)
        timings["radar"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    log.info("world %s: %d frames rendered in %.1f s", world_id, n_frames, timings["render"])
    return _outcome(world_id, seed, "ok", keys, timings,
                    [int(f.door_visible.sum()) for f in frames])


def world_source(seed: int) -> str:
    """A world's ``source`` in the manifest (its frames add ``frame=<k>``)."""
    return f"sim2radar.worlds seed={int(seed)}"


def _outcome(world_id: str, seed: int, status: str, keys: dict, timings: dict,
             visible: list[int]) -> Outcome:
    return Outcome(world_id, status, artifacts=keys, timings_s=timings, seed=int(seed),
                   source=world_source(seed),
                   measured={"n_frames": len(visible), "doors_visible": visible})


def _simulate_radar(world, frames, radar, store, keys, seed, world_id) -> None:
    """Radar point clouds of every frame on the world's ground-truth geometry."""
    from sim2radar.factory import LabelConfig
    from sim2radar.factory.pipeline import world_radar_frames
    from sim2radar.radar import RadarConfig, load_radar_config
    from sim2radar.storage import radar_frames_to_table

    radar_cfg = radar if isinstance(radar, RadarConfig) else load_radar_config(radar)
    labels = LabelConfig()
    points, seconds, boxes = world_radar_frames(world.meshes, frames, radar_cfg, labels)
    table = radar_frames_to_table(
        scene_id=world_id, radar_to_world=[f.radar_to_world for f in frames], points=points,
        boxes=boxes, box_labels=[["door"] * len(b) for b in boxes], sim_seconds=seconds)
    store.write("radar_points", keys["radar_points"], table,
                stage_version=RADAR_POINTS_STAGE_VERSION,
                provenance={"seed": int(seed),
                            "inputs": {"scene": keys["scene_meshes"],
                                       "world_frames": keys["world_frames"]},
                            "config": {"radar": radar_cfg.to_dict(), "seed": int(seed)},
                            "timings_s": {"simulate": float(sum(seconds))},
                            "extra": {"world_id": world_id,
                                      "labels": "doors the radar sees (visibility >= "
                                                f"{labels.min_visibility})"}})


def _stage_version() -> int:
    from sim2radar.worlds import STAGE_VERSION

    return STAGE_VERSION


def _render_version() -> int:
    from sim2radar.worlds import RENDER_VERSION

    return RENDER_VERSION


def failed_world(seed: int, error: BaseException | str) -> Outcome:
    """A ``failed`` outcome for world ``seed``."""
    from sim2radar.storage.worlds import world_id_for

    return Outcome.failed(world_id_for(seed), error, seed=int(seed), source=world_source(seed))


class WorldsRequest(BaseModel):
    """One run of the ``worlds`` job: procedural worlds rendered into the store.

    Attributes
    ----------
    seeds : world seeds (one seed -> one world)
    n_frames : frames along each world's trajectory
    store : artifact store root (local path or fsspec URI)
    dataset : manifest name
    world, rig : the generator's and the camera rig's settings
    trajectory_seed : seed of the rig's walk
    force : recompute even when artifacts exist
    radar : also simulate radar point clouds per frame with this preset / YAML, or None
    run : how many worlds at once (:class:`~sim2radar.tasks.runner.RunOptions`)
    """

    model_config = ConfigDict(extra="forbid")

    seeds: list[int] = Field(min_length=1)
    n_frames: int = Field(4, ge=1)
    store: str = "out/store"
    dataset: str = "worlds"
    world: WorldConfig = WorldConfig()
    rig: RigConfig = RigConfig()
    trajectory_seed: int = 0
    force: bool = False
    radar: str | None = None
    run: RunOptions = RunOptions()


def _world_unit(seed: int, run: StepRun, *, request: WorldsRequest) -> Outcome:
    return generate_world_artifacts(seed, request.n_frames, request.store, request.world,
                                    request.rig, trajectory_seed=request.trajectory_seed,
                                    force=request.force, radar=request.radar)


def generate_worlds(request: WorldsRequest, runner: Runner) -> RunSummary:
    """The ``worlds`` job: every world of ``request`` generated, rendered and recorded in the
    dataset manifest; a failing world is recorded ``failed`` and the others finish.

    Returns
    -------
    dict — :func:`sim2radar.tasks.common.summarize`'s (``outcomes``: the worlds)
    """
    units = Units(job="worlds", what="world", task="generate-world",
                  items=tuple(int(s) for s in request.seeds),
                  work=functools.partial(_world_unit, request=request), failed=failed_world,
                  name=world_id_for, store=request.store, dataset=request.dataset)
    summary = summarize(request.store, request.dataset, runner.run(units))
    log.info("generate-worlds: %s into %s (dataset %s)", summary["counts"], summary["store"],
             request.dataset)
    return summary
