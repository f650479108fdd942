"""The factory's main job, per world: procedural world -> (reconstructed | ground-truth)
geometry -> radar frames with door boxes -> the artifact store. Keys, caching, store I/O and
outcome records only: the science is in :mod:`sim2radar.factory` (spec, per-frame pipeline),
:mod:`sim2radar.tasks.steps` runs the reconstruction's steps, :mod:`sim2radar.flows.generate_dataset` makes every
step a Prefect task (the plain loop calls the same functions).

Per world seed, :func:`generate_world_dataset`:

1. makes sure the world's artifacts exist (``scene_meshes``, ``world_specs``, ``world_frames``
   through :func:`sim2radar.tasks.worlds.generate_world_artifacts`: the same content keys as
   ``sim2radar worlds generate``, so worlds rendered before are reused, not re-rendered);
2. per frame and geometry computes a ``dataset_frames`` content key from (world_frames key,
   world scene_meshes key, frame index, geometry, resolved radar config, resolved
   reconstruction config for ``reconstructed``, run seed, :data:`DATASET_STAGE_VERSION`); an
   existing artifact is read back (status ``skipped``), a missing one is computed:

   * ``ground_truth``: the radar is simulated on the world's own meshes at the frame's
     ``radar_to_world`` (one :class:`~sim2radar.radar.RadarScene` per world); labels are the
     ground-truth door boxes in the radar frame that the radar sees (at least
     ``labels.min_visibility`` of the doorway unoccluded, in FOV and range:
     :func:`sim2radar.factory.labels.radar_visibility` on the world's meshes);
   * ``reconstructed`` (the paper's pipeline): :func:`sim2radar.reconstruct.reconstruct` on the
     frame's RGB + LiDAR, meshes moved into the rig's radar frame
     (``inv(radar_to_world) @ camera_to_world``), radar simulated on them; labels are the
     reconstructed door boxes in the radar frame that the radar sees on the reconstructed
     geometry (the same visibility rule), the paper's pre-training pseudo-labels. The
     ground-truth doors the radar sees are stored alongside for scoring. The reconstruction
     itself is cached as its own ``scene_meshes`` + ``reconstruction`` artifacts
     (:func:`sim2radar.storage.reconstruction.write_scene_artifacts`), so changing only the
     radar re-simulates without re-reconstructing;

3. one failing frame is recorded as ``failed`` (with its error) and the other frames finish; a
   failing world (bad config, generator error) is recorded as ``failed`` and the other worlds
   finish. Manifest rows: one per world (``world_000007``) and one per frame
   (``world_000007_f002``).

The ``dataset_frames`` schema is declared here (registered on import).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from sim2radar.storage import ArtifactStore, content_key, meshes_from_table
from sim2radar.storage.frames import dataset_frame_from_table, dataset_frame_to_table
from sim2radar.storage.schemas import DATASET_FRAMES as DATASET_FRAMES_SCHEMA
from sim2radar.tasks.common import (
    FRAME_ROW,
    failed_scene_ids,
    jsonable,
    open_store,
)
from sim2radar.tasks.steps import call_step, reconstruction_steps

from sim2radar.datasets.splits import split_groups as split_worlds
from sim2radar.evaluate.dataset import LABEL_IOU_THRESHOLD
from sim2radar.factory.frames import NEAR_BOX_MARGIN_M, DatasetFrame, points_near_boxes
from sim2radar.factory.labels import (
    DEFAULT_POINT_CLOUD_RANGE_M,
    boxes_in_point_cloud_range,
)
from sim2radar.factory.pipeline import frame_id_for, with_material
from sim2radar.factory.seeds import frame_seed
from sim2radar.factory.spec import (
    GEOMETRIES,
    DatasetSpec,
    as_spec,
    dataset_metadata,
    resolve_spec,
)

__all__ = [
    "DATASET_STAGE_VERSION",
    "DATASET_FRAMES_SCHEMA",
    "GEOMETRIES",
    "DatasetSpec",
    "FrameOutcome",
    "WorldDatasetOutcome",
    "DatasetFrame",
    "resolve_spec",
    "frame_key",
    "frame_id_for",
    "generate_world_dataset",
    "failed_world_outcome",
    "failed_scene_outcome",
    "outcomes_from_summary",
    "record_world_dataset",
    "read_dataset_frame",
    "export_openpcdet",
    "split_worlds",
    "summarize_dataset",
    "generate_dataset_plain",
    "world_bev_pngs",
    "outcomes_from_manifest",
    "export_store_dataset",
    "failed_world_seeds",
    "points_near_boxes",
    "NEAR_BOX_MARGIN_M",
]

log = logging.getLogger(__name__)

#: Bump when a ``dataset_frames`` artifact of the same inputs changes (labels, filtering,
#: table logic): every dataset frame is recomputed, world renders and reconstructions are not.
DATASET_STAGE_VERSION = 3
#: (2: door labels need the radar to see >= LabelConfig.min_visibility of the doorway instead
#: of only the box centre in FOV and range; label visibility and Doppler stored; derived
#: receiver noise in the ray tracer. 3: the reference radar runs TI's cascade detection chain
#: on a moving rig's full chirp cube, the IF filter rolls off instead of deleting paths)
#: Short tags used in frame ids and artifact maps.
_TAG = {"ground_truth": "gt", "reconstructed": "rec"}


# ---------------------------------------------------------------------------------------------
# Keys and ids
# ---------------------------------------------------------------------------------------------
def frame_key(world_keys: dict[str, str], frame_index: int, geometry: str,
              spec: DatasetSpec) -> str:
    """Content key of one ``dataset_frames`` artifact."""
    config: dict[str, Any] = {
        "frame_index": int(frame_index),
        "geometry": geometry,
        "radar": spec.radar.to_dict(),
        "seed": spec.seed,
        "class_name": spec.class_name,
        "labels": spec.labels.model_dump(),
    }
    if spec.material_override is not None:
        config["material_override"] = spec.material_override
    if spec.moving:
        config["motion"] = spec.motion.model_dump(mode="json")
    if geometry == "reconstructed":
        config["reconstruction"] = spec.reconstruction.to_dict()
    return content_key(
        stage="dataset_frames", stage_version=DATASET_STAGE_VERSION,
        inputs={"world_frames": world_keys["world_frames"],
                "scene_meshes": world_keys["scene_meshes"]},
        config=config,
    )


def _reconstruction_keys(frame, camera_to_target: np.ndarray, config) -> dict[str, str]:
    """Keys of this frame's reconstruction artifacts (computed up front so a cached
    reconstruction is read instead of recomputed)."""
    from sim2radar.storage.reconstruction import reconstruction_keys

    from sim2radar.reconstruct.pipeline import STAGE_VERSION

    return reconstruction_keys({"image": _digest(frame)}, config.to_dict(), camera_to_target,
                               stage_version=STAGE_VERSION)


# ---------------------------------------------------------------------------------------------
# Outcomes
# ---------------------------------------------------------------------------------------------
@dataclasses.dataclass
class FrameOutcome:
    """What happened to one world frame (one manifest row ``<world>_f<k>``).

    Attributes
    ----------
    frame_id, world_id : str
    seed, frame_index : int
    status : ``ok`` | ``skipped`` | ``failed``
    error : str — ``"[geometry] ExceptionType: message"`` of each failed geometry
    artifacts : dict — ``dataset_frames/<geometry>`` (and reconstruction stages) -> key
    timings_s : dict — ``render``, ``reconstruct``, ``simulate_<geometry>`` [s] (compute time,
        also for cached frames: read from the artifacts)
    n_points, n_labels : dict — geometry -> points / labelled boxes
    n_gt_doors : int — ground-truth doors the radar sees
    gt_points_near : dict — geometry -> (G,) radar points near each GT door
    comparison : dict — ``both`` geometries: ``points_ratio`` (rec / gt), ``chamfer_m``
    label_match : dict — geometry -> ``tp``, ``n_pred``, ``n_gt``: labels matched one-to-one
        to ground-truth doors in view at 3D IoU >= :data:`LABEL_IOU_THRESHOLD`
    """

    frame_id: str
    world_id: str
    seed: int
    frame_index: int
    status: str
    error: str = ""
    artifacts: dict[str, str] = dataclasses.field(default_factory=dict)
    timings_s: dict[str, float] = dataclasses.field(default_factory=dict)
    n_points: dict[str, int] = dataclasses.field(default_factory=dict)
    n_labels: dict[str, int] = dataclasses.field(default_factory=dict)
    n_gt_doors: int = 0
    gt_points_near: dict[str, list[int]] = dataclasses.field(default_factory=dict)
    comparison: dict[str, float] = dataclasses.field(default_factory=dict)
    label_match: dict[str, dict[str, int]] = dataclasses.field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return jsonable(dataclasses.asdict(self))


@dataclasses.dataclass
class WorldDatasetOutcome:
    """What happened to one world (manifest row ``world_<seed>``) and its frames.

    Attributes
    ----------
    world_id : str; seed : int
    status : ``ok`` (something computed), ``skipped`` (all cached) or ``failed`` (the world
        itself or any of its frames failed)
    error : str — world-level error, or a count of failed frames
    artifacts : dict — world stage -> key (``scene_meshes``, ``world_specs``, ``world_frames``)
    timings_s : dict — ``world`` (generate/render or cache check), ``frames``, ``total`` [s]
        (a capture scene: wall seconds per stage)
    frames : list[FrameOutcome]
    source : str — where the scene came from (manifest ``source``; default: the world seed)
    """

    world_id: str
    seed: int
    status: str
    error: str = ""
    artifacts: dict[str, str] = dataclasses.field(default_factory=dict)
    timings_s: dict[str, float] = dataclasses.field(default_factory=dict)
    frames: list[FrameOutcome] = dataclasses.field(default_factory=list)
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = jsonable(dataclasses.asdict(self))
        d["frames"] = [f.to_dict() for f in self.frames]
        return d


def outcomes_from_summary(summary: dict[str, Any]) -> list[WorldDatasetOutcome]:
    """The world outcomes of a summary dict (e.g. returned by the Prefect flow)."""
    out = []
    for w in summary["worlds"]:
        frames = [FrameOutcome(**f) for f in w["frames"]]
        out.append(WorldDatasetOutcome(**{**w, "frames": frames}))
    return out


def failed_scene_outcome(scene_id: str, error: BaseException | str, *, seed: int = -1,
                         source: str = "") -> WorldDatasetOutcome:
    """A ``failed`` outcome for a world or capture scene (``"Type: message"`` error text)."""
    text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
    return WorldDatasetOutcome(scene_id, int(seed), "failed", error=text, source=source)


def failed_world_outcome(seed: int, error: BaseException | str) -> WorldDatasetOutcome:
    """A ``failed`` outcome for world ``seed``."""
    from sim2radar.storage.worlds import world_id_for

    return failed_scene_outcome(world_id_for(seed), error, seed=seed)


# ---------------------------------------------------------------------------------------------
# One frame, one geometry
# ---------------------------------------------------------------------------------------------
def read_dataset_frame(store: str | os.PathLike | ArtifactStore, key: str) -> DatasetFrame:
    """Read one ``dataset_frames`` artifact back."""
    return dataset_frame_from_table(open_store(store).read("dataset_frames", key))


def _world_frame_source(frame, world_id: str, spec: DatasetSpec):
    """A world frame as a :class:`~sim2radar.tasks.steps.FrameSource`: its reconstruction goes into the
    rig's radar frame (``inv(radar_to_world) @ camera_to_world``); ``oracle`` backends get the
    frame as ground truth."""
    from sim2radar.storage.reconstruction import stage_keys
    from sim2radar.tasks.steps import FrameSource

    from sim2radar.factory.pipeline import world_frame_input
    from sim2radar.reconstruct.pipeline import STAGE_VERSION

    cam_to_radar = np.linalg.inv(frame.radar_to_world) @ frame.camera_to_world
    inputs = {"image": _digest(frame)}
    keys = {**stage_keys(inputs, spec.reconstruction.to_dict(), stage_version=STAGE_VERSION),
            **_reconstruction_keys(frame, cam_to_radar, spec.reconstruction)}
    return FrameSource(frame_id_for(frame.seed, frame.frame_index),
                       f"{world_id} frame {frame.frame_index}",
                       lambda: (world_frame_input(frame), ""), inputs, keys,
                       camera_to_target=cam_to_radar, ground_truth=frame, seed=frame.seed)


def _reconstructed_frame(frame, world_id, world_scene, store, spec, radar_seed,
                         fresh: bool = False) -> tuple[DatasetFrame, dict[str, str]]:
    """The paper's pipeline on one world frame, from its reconstruction in the store (made by
    the reconstruction steps before; ``fresh``: in this run)."""
    from sim2radar.storage.reconstruction import read_reconstruction

    from sim2radar.factory.pipeline import reconstructed_frame

    cam_to_radar = np.linalg.inv(frame.radar_to_world) @ frame.camera_to_world
    rkeys = _reconstruction_keys(frame, cam_to_radar, spec.reconstruction)
    meshes = meshes_from_table(store.read("scene_meshes", rkeys["scene_meshes"]))
    rec = read_reconstruction(store, rkeys["reconstruction"])
    info = {"fallbacks": rec["info"].get("fallbacks", []), "cached": not fresh}
    if fresh:
        info["n_segments"] = len(rec["segment_labels"])
    df = reconstructed_frame(frame, world_id, world_scene, spec, radar_seed, meshes=meshes,
                             door_boxes=rec["door_boxes"],
                             reconstruct_s=float(rec["timings_s"].get("total", 0.0)),
                             stats={"reconstruction": info, "reconstruction_keys": rkeys})
    return df, rkeys


def _digest(frame) -> str:
    from sim2radar.storage.reconstruction import frame_digest

    return frame_digest(frame.rgb, frame.lidar_points, frame.rig_calibration)


# ---------------------------------------------------------------------------------------------
# One world
# ---------------------------------------------------------------------------------------------
def _upstream_verifies(st: ArtifactStore, rkeys: dict[str, str], spec) -> bool:
    """Whether a cached frame's reconstruction artifacts (scene meshes, reconstruction and the
    depth / segment / material steps it was built from) all verify. ``exists`` moves one that
    does not into quarantine, so the frame is recomputed and the store healed by this run. The
    steps' keys come from the reconstruction's recorded image digest: no frame is loaded."""
    from sim2radar.storage.reconstruction import stage_keys

    from sim2radar.reconstruct.pipeline import STAGE_VERSION

    if not st.all_exist(rkeys):
        return False
    if "reconstruction" not in rkeys:
        return True
    inputs = st.read_provenance("reconstruction", rkeys["reconstruction"]).get("inputs") or {}
    steps = stage_keys(inputs, spec.reconstruction.to_dict(), stage_version=STAGE_VERSION)
    # (stage_keys' own scene_meshes / reconstruction keys are for the camera frame; the
    # frame's, in the radar frame, are rkeys)
    return st.all_exist({s: steps[s] for s in ("depth_maps", "segmentations",
                                               "material_labels")})


class _WorldInputs:
    """Lazily loaded world geometry and frames (only when some frame must be computed)."""

    def __init__(self, store: ArtifactStore, keys: dict[str, str],
                 material_override: str | None = None) -> None:
        self.store, self.keys = store, keys
        self.material_override = material_override
        self._frames = None
        self._radar_scene = None

    def frames(self):
        if self._frames is None:
            from sim2radar.storage.worlds import frames_from_table

            self._frames = frames_from_table(self.store.read("world_frames",
                                                             self.keys["world_frames"]))
        return self._frames

    def radar_scene(self):
        if self._radar_scene is None:
            from sim2radar.radar import RadarScene

            meshes = meshes_from_table(self.store.read("scene_meshes", self.keys["scene_meshes"]))
            self._radar_scene = RadarScene(with_material(meshes, self.material_override))
        return self._radar_scene

    def release(self) -> None:
        """Drop the decoded frames and the Mitsuba scene now, in the thread that built them
        (step tasks may hold these inputs as parameters after the world is done; the
        scene's Dr.Jit objects are then not left for another thread to free)."""
        self._frames = None
        self._radar_scene = None


def _fill_frame_outcome(fo: FrameOutcome, df: DatasetFrame) -> None:
    fo.n_points[df.geometry] = int(len(df.points))
    fo.n_labels[df.geometry] = int(len(df.boxes))
    fo.n_gt_doors = int(len(df.gt_boxes))
    fo.gt_points_near[df.geometry] = [int(v) for v in df.gt_points_near]
    t = df.timings_s
    fo.timings_s["render"] = float(t.get("render", 0.0))
    if "reconstruct" in t:
        fo.timings_s["reconstruct"] = float(t["reconstruct"])
    fo.timings_s[f"simulate_{df.geometry}"] = float(t.get("simulate", 0.0))
    from sim2radar.evaluate.reconstruction import match_boxes

    m = match_boxes(df.boxes, df.gt_boxes, LABEL_IOU_THRESHOLD)
    fo.label_match[df.geometry] = {"tp": int(m["tp"]), "n_pred": int(m["n_pred"]),
                                   "n_gt": int(m["n_gt"])}


def _compare(gt: DatasetFrame, rec: DatasetFrame) -> dict[str, float]:
    from sim2radar.evaluate.dataset import compare_frames

    return compare_frames(gt.points, rec.points)


def generate_world_dataset(
    seed: int,
    spec: DatasetSpec | dict,
    store: str | os.PathLike | ArtifactStore = "out/store",
    *,
    force: bool = False,
    keep_frames: bool = False,
    n_frames: int | None = None,
    run: Callable[..., Any] = call_step,
) -> WorldDatasetOutcome:
    """Make (or find cached) every dataset frame of world ``seed``, step by step: ``render``
    (the world's artifacts), per frame the reconstruction's steps (``reconstructed``, when its
    reconstruction is not cached: :func:`sim2radar.tasks.steps.reconstruction_steps`) and one
    ``simulate`` per geometry for the frames still to compute, each through
    ``run(stage, fn, *args)`` (plain calls, or Prefect tasks in :mod:`sim2radar.flows.generate_dataset`).

    Parameters
    ----------
    seed : int — world seed (one seed -> one world)
    spec : DatasetSpec (or its :meth:`~DatasetSpec.to_dict`)
    store : store root (path / URI) or ArtifactStore
    force : bool — recompute the dataset frames (world renders and reconstructions stay cached)
    keep_frames : bool — attach the decoded :class:`DatasetFrame` objects as
        ``outcome.frames[i].data`` (tests, notebooks)
    n_frames : int, optional — frames of this world (default ``spec.frames_per_world``)

    Returns
    -------
    WorldDatasetOutcome — a world that cannot be generated raises (the caller records it);
    a failing frame is recorded in its FrameOutcome and does not raise.
    """
    from sim2radar.storage.worlds import world_id_for

    t_start = time.perf_counter()
    spec = as_spec(spec)
    st = open_store(store)
    world_id = world_id_for(seed)
    n_frames = spec.frames_per_world if n_frames is None else int(n_frames)
    wo = run("render", render_world, int(seed), n_frames, st, spec)
    keys = dict(wo.artifacts)
    inputs = _WorldInputs(st, keys, spec.material_override)
    timings = {"world": time.perf_counter() - t_start}
    computed_any = wo.status == "ok"
    frames_out = [FrameOutcome(frame_id_for(seed, k), world_id, int(seed), k, "skipped")
                  for k in range(n_frames)]
    decoded: list[dict[str, DatasetFrame]] = [{} for _ in range(n_frames)]
    errors: list[list[str]] = [[] for _ in range(n_frames)]

    def fail(k: int, geometry: str, error: str) -> None:
        log.error("%s [%s] failed: %s", frames_out[k].frame_id, geometry, error)
        errors[k].append(f"[{geometry}] {error}")

    def done(k: int, df: DatasetFrame, rkeys: dict) -> None:
        fo = frames_out[k]
        fo.artifacts.update({f"reconstruction/{s}": v for s, v in rkeys.items()})
        decoded[k][df.geometry] = df
        _fill_frame_outcome(fo, df)

    t_frames = time.perf_counter()
    # cached frames are read back; the others get their reconstruction steps (per frame) ...
    todo: dict[str, list[int]] = {g: [] for g in spec.geometries}
    fresh: dict[int, bool] = {}
    for k, fo in enumerate(frames_out):
        fo.artifacts.update({f"world/{s}": v for s, v in keys.items()})
        for geometry in spec.geometries:
            key = frame_key(keys, k, geometry, spec)
            fo.artifacts[f"dataset_frames/{geometry}"] = key
            try:
                if not force and st.exists("dataset_frames", key):
                    df = read_dataset_frame(st, key)
                    rkeys = df.stats.get("reconstruction_keys") or {}
                    if _upstream_verifies(st, rkeys, spec):
                        done(k, df, rkeys)
                        continue
                if geometry == "reconstructed":
                    src = _world_frame_source(inputs.frames()[k], world_id, spec)
                    fresh[k] = False
                    if not st.all_exist(src.keys):
                        steps = reconstruction_steps(src, spec.reconstruction, st, run)
                        fresh[k] = steps["scene"].status == "ok"
                todo[geometry].append(k)
            except Exception as exc:  # noqa: BLE001 - one broken frame must not stop the rest
                fail(k, geometry, f"{type(exc).__name__}: {exc}")
    # ... then one simulate step per geometry for the world's frames still to compute
    for geometry, ks in todo.items():
        if not ks:
            continue
        jobs = [(k, frames_out[k].artifacts[f"dataset_frames/{geometry}"], fresh.get(k, False))
                for k in ks]
        for k, df, rkeys, error in run("simulate", simulate_world_frames, inputs, jobs,
                                       geometry, world_id, st, spec):
            if error:
                fail(k, geometry, error)
                continue
            frames_out[k].status = "ok"
            computed_any = True
            done(k, df, rkeys)
    inputs.release()
    for k, fo in enumerate(frames_out):
        if errors[k]:
            fo.status, fo.error = "failed", "; ".join(errors[k])
        if len(decoded[k]) == 2:
            fo.comparison = _compare(decoded[k]["ground_truth"], decoded[k]["reconstructed"])
        if keep_frames:
            fo.data = decoded[k]  # type: ignore[attr-defined]
    timings["frames"] = time.perf_counter() - t_frames
    timings["total"] = time.perf_counter() - t_start
    n_failed = sum(f.status == "failed" for f in frames_out)
    status = "failed" if n_failed else ("ok" if computed_any else "skipped")
    error = f"{n_failed} of {len(frames_out)} frame(s) failed" if n_failed else ""
    return WorldDatasetOutcome(world_id, int(seed), status, error, keys, timings, frames_out)


def render_world(seed: int, n_frames: int, store, spec: DatasetSpec):
    """The ``render`` step: the world's meshes, spec and rendered frames
    (:func:`sim2radar.tasks.worlds.generate_world_artifacts`, the keys of ``sim2radar worlds
    generate``: worlds rendered before are reused)."""
    from sim2radar.tasks.worlds import generate_world_artifacts

    return generate_world_artifacts(int(seed), n_frames, store, spec.world, spec.rig,
                                    trajectory_seed=spec.seed, rgb=spec.render_rgb)


def simulate_world_frames(inputs: _WorldInputs, jobs: list[tuple[int, str, bool]],
                          geometry: str, world_id: str, store: ArtifactStore,
                          spec: DatasetSpec) -> list[tuple[int, Any, dict, str]]:
    """The ``simulate`` step of a world's frames in one geometry: per ``(frame index, key,
    fresh)`` the radar frame with its labels (:mod:`sim2radar.factory.pipeline`), written as
    ``dataset_frames/<key>`` (``reconstructed``: the reconstruction must be in the store,
    ``fresh`` when made in this run). Returns ``(k, frame, reconstruction keys, error)`` per
    job; a failing frame gets its error and the others go on."""
    out = []
    for k, key, fresh in jobs:
        try:
            df, rkeys = _simulate_world_frame(inputs, k, geometry, world_id, store, spec, fresh)
            store.write("dataset_frames", key, dataset_frame_to_table(df),
                        stage_version=DATASET_STAGE_VERSION,
                        provenance=_provenance(spec, inputs.keys, df, geometry, rkeys))
            out.append((k, df, rkeys, ""))
        except Exception as exc:  # noqa: BLE001 - one broken frame must not stop the rest
            out.append((k, None, {}, f"{type(exc).__name__}: {exc}"))
    return out


def _simulate_world_frame(inputs: _WorldInputs, k: int, geometry: str, world_id: str,
                          store: ArtifactStore, spec: DatasetSpec,
                          fresh: bool) -> tuple[DatasetFrame, dict]:
    frame = inputs.frames()[k]
    radar_seed = frame_seed(spec.seed, frame.seed, k)
    scene = inputs.radar_scene()  # the world's meshes: the GT radar and the labels' visibility
    if geometry == "ground_truth":
        from sim2radar.factory.pipeline import ground_truth_frame

        return ground_truth_frame(frame, world_id, scene, spec, radar_seed), {}
    return _reconstructed_frame(frame, world_id, scene, store, spec, radar_seed, fresh)


def _provenance(spec, keys, df: DatasetFrame, geometry, rkeys) -> dict:
    config = {"radar": spec.radar.to_dict(), "geometry": geometry,
              "frame_index": df.frame_index, "class_name": spec.class_name}
    if geometry == "reconstructed":
        config["reconstruction"] = spec.reconstruction.to_dict()
    return {
        "inputs": {"world_frames": keys["world_frames"], "scene_meshes": keys["scene_meshes"],
                   **{f"reconstruction/{s}": v for s, v in rkeys.items()}},
        "config": config,
        "seed": spec.seed,
        "timings_s": dict(df.timings_s),
        "extra": {"frame_id": df.frame_id, "world_seed": df.seed,
                  "radar_seed": df.stats.get("radar_seed")},
    }


# ---------------------------------------------------------------------------------------------
# Manifest, summary
# ---------------------------------------------------------------------------------------------
def record_world_dataset(store, dataset: str, outcome: WorldDatasetOutcome) -> list[dict]:
    """Upsert the world's manifest row and one row per frame; returns the rows."""
    m = open_store(store).manifest(dataset)
    source = outcome.source or f"sim2radar.worlds seed={outcome.seed}"
    rows = [m.upsert(outcome.world_id, outcome.status, error=outcome.error,
                     artifacts=outcome.artifacts, timings_s=outcome.timings_s, source=source)]
    for f in outcome.frames:
        rows.append(m.upsert(f.frame_id, f.status, error=f.error, artifacts=f.artifacts,
                             timings_s=f.timings_s, source=f"{source} frame={f.frame_index}"))
    return rows


def summarize_dataset(store, dataset: str, spec: DatasetSpec | dict,
                      outcomes: list[WorldDatasetOutcome]) -> dict[str, Any]:
    """The run summary: counts, per-geometry table and per-stage seconds.

    Returns
    -------
    dict — ``store``, ``dataset``, ``counts`` (worlds by status), ``frame_counts`` (frames by
    status), ``geometry`` -> {``frames``, ``points_per_frame``, ``labels_per_frame``,
    ``gt_doors_per_frame``, ``frac_frames_with_label``, ``frac_gt_doors_with_points``,
    ``label_recall`` / ``label_precision`` (labels vs ground-truth doors in the radar's view at
    3D IoU >= 0.3; 1 for ground_truth by construction; GT doors outside the camera's narrower
    view count as misses for ``reconstructed``)},
    ``seconds_per_frame`` -> {stage: mean [s]}, ``comparison`` (both geometries:
    ``points_ratio``, ``chamfer_m`` means and per frame), ``worlds`` (outcome dicts).
    """
    from sim2radar.evaluate.dataset import geometry_metrics, stage_seconds

    spec = as_spec(spec)
    st = open_store(store)
    frames = [f for o in outcomes for f in o.frames]
    per_geometry = geometry_metrics(frames, spec.geometries)
    seconds = stage_seconds(frames)
    comp = [f for f in frames if f.comparison]
    summary: dict[str, Any] = {
        "store": st.root,
        "dataset": dataset,
        "counts": {k: sum(o.status == k for o in outcomes) for k in ("ok", "skipped", "failed")},
        "frame_counts": {k: sum(f.status == k for f in frames)
                         for k in ("ok", "skipped", "failed")},
        "geometry": per_geometry,
        "seconds_per_frame": seconds,
        "worlds": [o.to_dict() for o in outcomes],
        "manifest": st._join("manifests", dataset),
    }
    if comp:
        from sim2radar.evaluate.dataset import finite_mean

        summary["comparison"] = {
            "points_ratio": finite_mean(f.comparison["points_ratio"] for f in comp),
            "chamfer_m": finite_mean(f.comparison["chamfer_m"] for f in comp),
            "frames": {f.frame_id: f.comparison for f in comp},
        }
    return summary


# ---------------------------------------------------------------------------------------------
# OpenPCDet export
# ---------------------------------------------------------------------------------------------
def export_openpcdet(store, outcomes: list[WorldDatasetOutcome], export_dir: str | os.PathLike,
                     geometry: str, *, seed: int = 0,
                     label_range_m: Sequence[float] | None = DEFAULT_POINT_CLOUD_RANGE_M,
                     with_doppler: bool = False,
                     splits: dict[str, list[str]] | None = None,
                     metadata: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write the frames of one geometry in OpenPCDet's custom layout with
    :func:`sim2radar.datasets.write_dataset`.

    ``points/<frame_id>.npy`` (N, 4) float32 x, y, z [m], intensity [dB] (+ doppler [m/s] as a
    5th column with ``with_doppler``); ``labels/<frame_id>.txt`` ``x y z dx dy dz heading
    <class>``, only labels whose centre lies in ``label_range_m`` (the detector's point-cloud
    range; None keeps all); ``ImageSets/{train,val,test}.txt`` split by world (seeded,
    :func:`split_worlds`, or the given ``splits``: split name -> world ids); ``dataset.json``
    (:func:`sim2radar.datasets.write_metadata`): ``metadata`` plus the counts, the label rule
    and the worlds of each split. Only frames whose geometry artifact exists are exported.

    Returns ``{"root", "frames", "labels", "labels_dropped_out_of_range", "splits": {name:
    n_frames}}``.
    """
    from sim2radar.datasets import Frame, write_dataset

    st = open_store(store)
    frames, world_of = [], {}
    n_labels = n_dropped = 0
    for o in outcomes:
        for f in o.frames:
            key = f.artifacts.get(f"dataset_frames/{geometry}")
            if key is None or geometry not in f.n_points:
                continue
            df = read_dataset_frame(st, key)
            keep = boxes_in_point_cloud_range(df.boxes, label_range_m)
            n_labels += int(keep.sum())
            n_dropped += int((~keep).sum())
            points = df.points_with_doppler if with_doppler else df.points
            frames.append(Frame(df.frame_id, points, df.boxes[keep],
                                tuple(n for n, k in zip(df.box_labels, keep, strict=True) if k)))
            world_of[df.frame_id] = df.world_id
    worlds = splits or split_worlds(sorted(set(world_of.values())), seed)
    by_split = {name: [fid for fid in sorted(world_of) if world_of[fid] in set(ws)]
                for name, ws in worlds.items()}
    root = Path(export_dir)
    write_dataset(root, frames, by_split)
    out = {"root": str(root), "frames": len(frames), "labels": n_labels,
           "labels_dropped_out_of_range": n_dropped,
           "splits": {k: len(v) for k, v in by_split.items()}, "warnings": []}
    empty = [k for k, v in by_split.items() if not v]
    if not frames:
        out["warnings"].append(
            "no frame to export: every world/scene failed or was skipped (the manifest's error "
            "column says why); the folder holds an empty dataset")
    elif empty:
        n_groups = len(set(world_of.values()))
        out["warnings"].append(
            f"split(s) {empty} are empty: {n_groups} world(s)/scene(s) cannot fill train, val "
            "and test (the split is by world); generate more worlds or scenes, or train with "
            "another split")
    for w in out["warnings"]:
        log.warning("%s: %s", root, w)
    from datetime import UTC, datetime

    from sim2radar.datasets import write_metadata

    write_metadata(root, {
        **(metadata or {}), **out, "geometry": geometry,
        "point_columns": ["x_m", "y_m", "z_m", "intensity_db"] + (
            ["doppler_mps"] if with_doppler else []),
        "label_range_m": None if label_range_m is None else list(label_range_m),
        "worlds": {k: sorted(set(v)) for k, v in worlds.items()},
        "exported_at": datetime.now(UTC).isoformat(timespec="seconds"),
    })
    return out


def outcomes_from_manifest(store, dataset: str) -> list[WorldDatasetOutcome]:
    """The world outcomes of a finished dataset, rebuilt from its manifest (frame rows
    ``world_<seed>_f<k>`` with ``dataset_frames/<geometry>`` artifacts): what
    :func:`export_openpcdet` needs to export a dataset of an earlier run. Geometries whose
    artifact is missing from the store are left out of each frame."""
    st = open_store(store)
    rows = st.manifest(dataset).rows()
    if not rows:
        raise ValueError(f"store {st.root}: dataset {dataset!r} has no manifest rows; "
                         f"known datasets: {st.manifests()}")
    worlds: dict[str, WorldDatasetOutcome] = {}
    for r in rows:
        m = FRAME_ROW.match(r["scene_id"])
        if m is None or r["status"] == "failed":
            continue
        world_id, k = m.group(1), m.group(2)
        o = worlds.setdefault(world_id, WorldDatasetOutcome(world_id, -1, "skipped"))
        fo = FrameOutcome(r["scene_id"], world_id, -1, int(k), r["status"],
                          artifacts=dict(r["artifacts"]))
        for name, key in r["artifacts"].items():
            if name.startswith("dataset_frames/") and st.exists("dataset_frames", key):
                fo.n_points[name.split("/", 1)[1]] = -1  # present; the count is in the frame
        o.frames.append(fo)
    return [worlds[w] for w in sorted(worlds)]


def failed_world_seeds(store, dataset: str) -> list[int]:
    """Seeds of the worlds the ``dataset`` manifest records as failed (``--retry-failed``)."""
    import re

    ids = failed_scene_ids(store, dataset)
    return sorted(int(m.group(1)) for i in ids if (m := re.match(r"^world_(\d+)$", i)))


def export_store_dataset(store, dataset: str, geometry: str, export_dir: str | os.PathLike,
                         *, seed: int = 0) -> dict[str, Any]:
    """Export ``geometry`` frames of a dataset already in the store (by its manifest) to
    OpenPCDet's layout, split by world with ``seed``; Doppler is exported when the frames came
    from the signal-level radar."""
    outcomes = outcomes_from_manifest(store, dataset)
    frames = [f for o in outcomes for f in o.frames if geometry in f.n_points]
    if not frames:
        raise ValueError(f"store dataset {dataset!r} has no {geometry!r} frames; choose the "
                         f"geometry with {dataset}:ground_truth or {dataset}:reconstructed")
    first = read_dataset_frame(store, frames[0].artifacts[f"dataset_frames/{geometry}"])
    fidelity = (first.stats.get("radar") or {}).get("fidelity", "raytrace")
    from sim2radar.factory.reference import stored_dataset_domain

    domain = stored_dataset_domain(fidelity, geometry)
    return export_openpcdet(store, outcomes, export_dir, geometry, seed=seed,
                            with_doppler=fidelity == "signal",
                            metadata={"domain": domain, "source": f"store dataset {dataset!r}"})


def world_bev_pngs(store, outcomes: list[WorldDatasetOutcome], png_dir: str | os.PathLike,
                   spec: DatasetSpec | dict) -> list[str]:
    """One bird's-eye-view PNG per world (or capture scene) and geometry
    (:func:`sim2radar.visualize.frames_bev_png`): every frame's radar points and labels in the
    first frame's radar frame."""
    from sim2radar.visualize import frames_bev_png

    spec = as_spec(spec)
    st = open_store(store)
    out = []
    for o in outcomes:
        for g in spec.geometries:
            dfs = [read_dataset_frame(st, f.artifacts[f"dataset_frames/{g}"])
                   for f in o.frames if g in f.n_points]
            if dfs:
                path = Path(png_dir) / f"{o.world_id}_{_TAG[g]}.png"
                out.append(str(frames_bev_png(dfs, path, class_name=spec.class_name,
                                              title=f"{o.world_id} [{g}]")))
    return out


# ---------------------------------------------------------------------------------------------
# The flow without the engine
# ---------------------------------------------------------------------------------------------
def generate_dataset_plain(
    seeds: Sequence[int],
    spec: DatasetSpec | dict,
    store: str | os.PathLike | ArtifactStore = "out/store",
    dataset: str = "generated",
    *,
    export_dir: str | os.PathLike | None = None,
    force: bool = False,
    on_world: Callable[[WorldDatasetOutcome], None] | None = None,
    frames_by_seed: dict[int, int] | None = None,
    splits: dict[str, list[str]] | None = None,
    export_doppler: bool = False,
    domain: str | None = None,
) -> dict[str, Any]:
    """The generate-dataset flow's semantics without the Prefect engine (notebooks, tests):
    worlds one after another, failures recorded, not raised. ``frames_by_seed`` overrides the
    frames of some worlds; ``splits`` (split -> world ids) and ``export_doppler`` go to the
    export. Returns :func:`summarize_dataset`'s dict (plus ``export`` when ``export_dir`` is
    given)."""
    spec = as_spec(spec)
    st = open_store(store)
    st.manifest(dataset)  # validates the name before any work
    outcomes = []
    for seed in seeds:
        try:
            outcome = generate_world_dataset(int(seed), spec, st, force=force,
                                             n_frames=(frames_by_seed or {}).get(int(seed)))
        except Exception as exc:  # noqa: BLE001 - one broken world must not stop the others
            log.error("world %s failed: %s: %s", seed, type(exc).__name__, exc)
            outcome = failed_world_outcome(seed, exc)
        record_world_dataset(st, dataset, outcome)
        outcomes.append(outcome)
        if on_world is not None:
            on_world(outcome)
    summary = summarize_dataset(st, dataset, spec, outcomes)
    if export_dir is not None:
        summary["export"] = export_all(st, outcomes, export_dir, spec, splits=splits,
                                       with_doppler=export_doppler, domain=domain)
    return summary


def export_all(store, outcomes, export_dir, spec: DatasetSpec | dict, *,
               splits: dict[str, list[str]] | None = None,
               with_doppler: bool = False, domain: str | None = None) -> dict[str, Any]:
    """Export every geometry of the run: straight into ``export_dir`` for one geometry, into
    ``export_dir/<geometry>`` for ``both``; ``domain`` labels the export (default: simulated)."""
    spec = as_spec(spec)
    opts = {"seed": spec.seed, "label_range_m": spec.export_label_range_m, "splits": splits,
            "with_doppler": with_doppler}
    if len(spec.geometries) == 1:
        g = spec.geometries[0]
        return {g: export_openpcdet(store, outcomes, export_dir, g, **opts,
                                    metadata=dataset_metadata(spec, g, domain))}
    return {g: export_openpcdet(store, outcomes, Path(export_dir) / g, g, **opts,
                                metadata=dataset_metadata(spec, g, domain))
            for g in spec.geometries}
