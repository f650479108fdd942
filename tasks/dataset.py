"""The factory's main job, per world: keys, caching, store I/O and outcome records around
:mod:`sim2radar.factory` (the per-frame science: :mod:`sim2radar.factory.pipeline`).

Per world seed, :func:`generate_world_dataset` makes sure the world's artifacts exist
(:func:`sim2radar.tasks.worlds.generate_world_artifacts`, the keys of ``sim2radar worlds
generate``); per frame and geometry it keys a ``dataset_frames`` artifact on (world keys,
frame index, geometry, resolved radar / reconstruction configs, run seed,
:data:`DATASET_STAGE_VERSION`) and reads it back when it exists (``skipped``, after checking
the reconstruction it was made from) or makes it: the reconstruction's steps
(:mod:`sim2radar.tasks.steps`, cached as their own artifacts, so changing only the radar
re-simulates without re-reconstructing), then one ``simulate`` step per geometry. A failing
frame is recorded ``failed`` and the others finish; a failing world raises for its caller to
record. Manifest rows: one per world (``world_000007``), one per frame
(``world_000007_f002``). :mod:`sim2radar.flows.generate_dataset` runs every step as a Prefect
task; a plain run calls the same functions (:mod:`sim2radar.tasks.runner`). The ``generate``
job's driver, which runs this per world, is :mod:`sim2radar.tasks.generate`.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sim2radar.datasets.splits import split_groups as split_worlds
from sim2radar.evaluate.dataset import LABEL_IOU_THRESHOLD
from sim2radar.factory.captures import CaptureSpec
from sim2radar.factory.export import export_frames
from sim2radar.factory.frames import NEAR_BOX_MARGIN_M, DatasetFrame, points_near_boxes
from sim2radar.factory.pipeline import frame_id_for, with_material
from sim2radar.factory.seeds import frame_seed
from sim2radar.factory.spec import (
    GEOMETRIES,
    DatasetSpec,
    dataset_metadata,
)
from sim2radar.storage import ArtifactStore, content_key, meshes_from_table
from sim2radar.storage.frames import dataset_frame_from_table, dataset_frame_to_table
from sim2radar.storage.schemas import DATASET_FRAMES as DATASET_FRAMES_SCHEMA
from sim2radar.storage.worlds import world_id_for
from sim2radar.tasks.common import (
    FRAME_ROW,
    Outcome,
    RunSummary,
    count_statuses,
    failed_scene_ids,
    open_store,
    summarize,
)
from sim2radar.tasks.runner import call_step
from sim2radar.tasks.steps import reconstruction_steps
from sim2radar.tasks.worlds import world_source

__all__ = [
    "DATASET_STAGE_VERSION",
    "DATASET_FRAMES_SCHEMA",
    "GEOMETRIES",
    "DatasetSpec",
    "DatasetFrame",
    "frame_key",
    "frame_id_for",
    "generate_world_dataset",
    "outcomes_from_summary",
    "read_dataset_frame",
    "export_openpcdet",
    "split_worlds",
    "summarize_dataset",
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
DATASET_STAGE_VERSION = 8
#: (2: door labels need the radar to see >= LabelConfig.min_visibility of the doorway instead
#: of only the box centre in FOV and range; label visibility and Doppler stored; derived
#: receiver noise in the ray tracer. 3: the reference radar runs TI's cascade detection chain
#: on a moving rig's full chirp cube, the IF filter rolls off instead of deleting paths.
#: 4: each point's offset from the world's first surface stored; R_max in the radar stats.
#: 5: the ray tracer weights each return by the antenna elements' two-way gain.
#: 6: the ray tracer's receiver noise drawn in two steps, channel-integrated power first: a new
#: noise stream of the same distribution. 7: the ray tracer's range-Doppler profile sums the
#: array's channels only, not the empty positions of its position grid. 8: the reference
#: radar's IF synthesis inverse-FFTs each Doppler group before forming the chirps: float32
#: rounding, so an ADC sample can land one LSB over)
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
    from sim2radar.reconstruct.pipeline import STAGE_VERSION
    from sim2radar.storage.reconstruction import reconstruction_keys

    return reconstruction_keys({"image": _digest(frame)}, config.to_dict(), camera_to_target,
                               stage_version=STAGE_VERSION)


def outcomes_from_summary(summary: dict[str, Any]) -> list[Outcome]:
    """The world outcomes of a summary dict (e.g. returned by the Prefect flow)."""
    return [Outcome.from_dict(d) for d in summary["outcomes"]]


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
    from sim2radar.factory.pipeline import world_frame_input
    from sim2radar.reconstruct.pipeline import STAGE_VERSION
    from sim2radar.storage.reconstruction import stage_keys
    from sim2radar.tasks.steps import FrameSource

    cam_to_radar = np.linalg.inv(frame.radar_to_world) @ frame.camera_to_world
    inputs = {"image": _digest(frame)}
    keys = {**stage_keys(inputs, spec.reconstruction.to_dict(), stage_version=STAGE_VERSION),
            **_reconstruction_keys(frame, cam_to_radar, spec.reconstruction)}
    return FrameSource(frame_id_for(frame.seed, frame.frame_index),
                       f"{world_id} frame {frame.frame_index}",
                       lambda: (world_frame_input(frame), ""), inputs, keys,
                       camera_to_target=cam_to_radar, ground_truth=frame, seed=frame.seed)


def _stored_keys(frame, spec) -> dict[str, str]:
    """The keys of a world frame's reconstruction in its rig's radar frame."""
    cam_to_radar = np.linalg.inv(frame.radar_to_world) @ frame.camera_to_world
    return _reconstruction_keys(frame, cam_to_radar, spec.reconstruction)


def _stored_view(frame, store, spec) -> tuple[list, np.ndarray, dict, dict[str, str]]:
    """A world frame's reconstruction from the store, in its rig's radar frame: meshes, door
    boxes, the reconstruction record and its keys."""
    from sim2radar.storage.reconstruction import read_reconstruction

    rkeys = _stored_keys(frame, spec)
    meshes = meshes_from_table(store.read("scene_meshes", rkeys["scene_meshes"]))
    rec = read_reconstruction(store, rkeys["reconstruction"])
    return meshes, np.asarray(rec["door_boxes"], np.float32).reshape(-1, 7), rec, rkeys


def _reconstructed_frame(frame, world_id, world_scene, store, spec, radar_seed,
                         fresh: bool = False, earlier_frames=()) -> tuple[DatasetFrame, dict[str, str]]:
    """The paper's pipeline on one world frame, from its reconstruction in the store (made by
    the reconstruction steps before; ``fresh``: in this run), fused with the reconstructions of
    ``earlier_frames`` (the previous frames of its trajectory, most recent first,
    ``reconstruction.fusion.frames`` of them; :func:`sim2radar.reconstruct.fusion.fuse_views`)."""
    from sim2radar.factory.pipeline import reconstructed_frame
    from sim2radar.storage import combine_provisional

    meshes, boxes, rec, rkeys = _stored_view(frame, store, spec)
    info = {"fallbacks": rec["info"].get("fallbacks", []), "cached": not fresh}
    own = store.provisional("reconstruction", rkeys["reconstruction"])
    fused_in = [store.provisional("reconstruction",
                                  _stored_keys(f, spec)["reconstruction"]) for f in earlier_frames]
    provisional = combine_provisional([own, *fused_in])
    if provisional:  # built on fallback materials: stored provisional, made again next run
        info["provisional"] = provisional
        info["material_fallbacks"] = int((own or {}).get("fallbacks", 0))
    if fresh:
        info["n_segments"] = len(rec["segment_labels"])
    if earlier_frames:
        from sim2radar.reconstruct.fusion import EarlierView, fuse_views

        radar_from_world = np.linalg.inv(frame.radar_to_world)
        views = [EarlierView(*_stored_view(f, store, spec)[:2], radar_from_world @ f.radar_to_world)
                 for f in earlier_frames]
        fused = fuse_views(meshes, boxes, views, frame.intrinsics,
                           radar_from_world @ frame.camera_to_world)
        meshes, boxes = fused.meshes, fused.door_boxes
        info["fusion"] = {"views": fused.views, "triangles_added": fused.triangles_added,
                          "boxes_added": fused.boxes_added,
                          "frames": [int(f.frame_index) for f in earlier_frames]}
    df = reconstructed_frame(frame, world_id, world_scene, spec, radar_seed, meshes=meshes,
                             door_boxes=boxes,
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
    from sim2radar.reconstruct.pipeline import STAGE_VERSION
    from sim2radar.storage.reconstruction import stage_keys

    if not st.all_cached(rkeys):
        return False
    if "reconstruction" not in rkeys:
        return True
    inputs = st.read_provenance("reconstruction", rkeys["reconstruction"]).get("inputs") or {}
    steps = stage_keys(inputs, spec.reconstruction.to_dict(), stage_version=STAGE_VERSION)
    # (stage_keys' own scene_meshes / reconstruction keys are for the camera frame; the
    # frame's, in the radar frame, are rkeys)
    return st.all_cached({s: steps[s] for s in ("depth_maps", "segmentations",
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


def frame_provisional(df: DatasetFrame) -> dict | None:
    """The ``provisional`` record of a dataset frame simulated from a reconstruction whose
    materials fell back (its own or a view fused into it), else None."""
    return (df.stats.get("reconstruction") or {}).get("provisional")


def _fill_frame_outcome(fo: Outcome, df: DatasetFrame) -> None:
    from sim2radar.evaluate.dataset import frame_measures

    provisional = frame_provisional(df)
    if provisional:  # segments that fell back in the geometry this frame was simulated from
        fo.measured["fallbacks"] = max(int(fo.measured.get("fallbacks", 0)),
                                       int(provisional["fallbacks"]))
        own = int((df.stats.get("reconstruction") or {}).get("material_fallbacks", 0))
        fo.measured["own_fallbacks"] = max(int(fo.measured.get("own_fallbacks", 0)), own)

    for name, value in frame_measures(df, LABEL_IOU_THRESHOLD).items():
        if isinstance(value, dict):
            fo.measured.setdefault(name, {}).update(value)
        else:
            fo.measured[name] = value
    t = df.timings_s
    fo.timings_s["render"] = float(t.get("render", 0.0))
    if "reconstruct" in t:
        fo.timings_s["reconstruct"] = float(t["reconstruct"])
    fo.timings_s[f"simulate_{df.geometry}"] = float(t.get("simulate", 0.0))


def _compare(gt: DatasetFrame, rec: DatasetFrame) -> dict[str, float]:
    from sim2radar.evaluate.dataset import compare_frames

    return compare_frames(gt.points, rec.points)


def generate_world_dataset(
    seed: int,
    spec: DatasetSpec,
    store: str | os.PathLike | ArtifactStore = "out/store",
    *,
    force: bool = False,
    keep_frames: bool = False,
    n_frames: int | None = None,
    run: Callable[..., Any] = call_step,
) -> Outcome:
    """Make (or find cached) every dataset frame of world ``seed``, step by step: ``render``
    (the world's artifacts), per frame the reconstruction's steps (``reconstructed``, when its
    reconstruction is not cached: :func:`sim2radar.tasks.steps.reconstruction_steps`) and one
    ``simulate`` per geometry for the frames still to compute, each through
    ``run(stage, fn, *args)`` (plain calls, or Prefect tasks in :mod:`sim2radar.flows.generate_dataset`).

    Parameters
    ----------
    seed : int — world seed (one seed -> one world)
    spec : DatasetSpec
    store : store root (path / URI) or ArtifactStore
    force : bool — recompute the dataset frames (world renders and reconstructions stay cached)
    keep_frames : bool — attach the decoded :class:`DatasetFrame` objects as
        ``outcome.parts[i].data`` (tests, notebooks)
    n_frames : int, optional — frames of this world (default ``spec.frames_per_world``)

    Returns
    -------
    Outcome — the world's, its frames as ``parts`` (``measured``: see
    :func:`sim2radar.evaluate.dataset.frame_measures`); a world that cannot be generated
    raises (the caller records it); a failing frame is recorded in its outcome and does not
    raise.
    """
    st = open_store(store)
    n_frames = spec.frames_per_world if n_frames is None else int(n_frames)
    with world_claim(st, seed, spec, n_frames):
        return _generate_world(seed, spec, st, force, keep_frames, n_frames, run)


def world_claim(st: ArtifactStore, seed: int, spec: DatasetSpec, n_frames: int):
    """One process at a time makes a world of a given spec in a local store (two runs on one
    store computed every world twice): a claim (:mod:`sim2radar.experiment.claims`) under
    ``<store>/claims/generate/``, waited for while another live process holds it — the waiter
    then finds that world's frames cached. A remote store has no claims (a no-op)."""
    import contextlib

    if not st.is_local:
        return contextlib.nullcontext()
    from sim2radar.experiment.claims import wait_and_claim

    key = content_key(stage="generate_world", stage_version=1, inputs={},
                      config={"seed": int(seed), "n_frames": int(n_frames),
                              "spec": spec.to_dict()})
    return wait_and_claim(
        Path(st.root) / "claims" / "generate", key, lambda: False,
        on_wait=lambda holder: log.warning(
            "world seed %d is being made by pid %s on %s for the same settings; waiting for "
            "it (its frames are then read back, not computed again)", int(seed),
            holder.get("pid"), holder.get("host")))


def _generate_world(seed: int, spec: DatasetSpec, st: ArtifactStore, force: bool,
                    keep_frames: bool, n_frames: int, run: Callable[..., Any]) -> Outcome:
    """The body of :func:`generate_world_dataset`, under its world's claim."""

    t_start = time.perf_counter()
    world_id = world_id_for(seed)
    wo = run("render", render_world, int(seed), n_frames, st, spec)
    keys = dict(wo.artifacts)
    inputs = _WorldInputs(st, keys, spec.material_override)
    timings = {"world": time.perf_counter() - t_start}
    computed_any = wo.status == "ok"
    frames_out = [Outcome(frame_id_for(seed, k), "skipped", seed=int(seed), index=k)
                  for k in range(n_frames)]
    decoded: list[dict[str, DatasetFrame]] = [{} for _ in range(n_frames)]
    errors: list[list[str]] = [[] for _ in range(n_frames)]

    def fail(k: int, geometry: str, error: str) -> None:
        log.error("%s [%s] failed: %s", frames_out[k].id, geometry, error)
        errors[k].append(f"[{geometry}] {error}")
        frames_out[k].artifacts.pop(f"dataset_frames/{geometry}", None)  # never written

    def done(k: int, df: DatasetFrame, rkeys: dict) -> None:
        fo = frames_out[k]
        fo.artifacts.update({f"reconstruction/{s}": v for s, v in rkeys.items()})
        decoded[k][df.geometry] = df
        _fill_frame_outcome(fo, df)

    t_frames = time.perf_counter()
    # cached frames are read back; the others get their reconstruction steps (per frame) ...
    todo: dict[str, list[int]] = {g: [] for g in spec.geometries}
    fresh: dict[int, bool] = {}
    stepped: set[int] = set()
    for k, fo in enumerate(frames_out):
        fo.artifacts.update({f"world/{s}": v for s, v in keys.items()})
        for geometry in spec.geometries:
            key = frame_key(keys, k, geometry, spec)
            fo.artifacts[f"dataset_frames/{geometry}"] = key
            try:
                if not force and st.cached("dataset_frames", key):
                    df = read_dataset_frame(st, key)
                    rkeys = df.stats.get("reconstruction_keys") or {}
                    if _upstream_verifies(st, rkeys, spec):
                        done(k, df, rkeys)
                        continue
                if geometry == "reconstructed":
                    fresh[k] = False
                    # this frame's reconstruction and those fused into it
                    for i in (k, *_earlier_indices(k, spec)):
                        src = _world_frame_source(inputs.frames()[i], world_id, spec)
                        # once per run: a provisional (fallback) one is asked again, not twice
                        if i not in stepped and not st.all_cached(src.keys):
                            steps = reconstruction_steps(src, spec.reconstruction, st, run,
                                                         label=f"f{i:03d}")
                            stepped.add(i)
                            fresh[i] = fresh.get(i, False) or steps["scene"].status == "ok"
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
                                       geometry, world_id, st, spec, label=geometry):
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
            fo.measured["comparison"] = _compare(decoded[k]["ground_truth"],
                                                 decoded[k]["reconstructed"])
        if keep_frames:
            fo.data = decoded[k]  # type: ignore[attr-defined]
    timings["frames"] = time.perf_counter() - t_frames
    timings["total"] = time.perf_counter() - t_start
    n_failed = sum(f.status == "failed" for f in frames_out)
    status = "failed" if n_failed else ("ok" if computed_any else "skipped")
    error = f"{n_failed} of {len(frames_out)} frame(s) failed" if n_failed else ""
    # segments whose material fell back, over the world's frames' own reconstructions
    measured = {"fallbacks": sum(int(f.measured.get("own_fallbacks", 0)) for f in frames_out)}
    return Outcome(world_id, status, error, keys, timings, world_source(seed), int(seed),
                   measured=measured, parts=frames_out)


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
                        provenance=_provenance(spec, inputs.keys, df, geometry, rkeys),
                        provisional=frame_provisional(df))
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
    earlier = [inputs.frames()[i] for i in _earlier_indices(k, spec)]
    return _reconstructed_frame(frame, world_id, scene, store, spec, radar_seed, fresh,
                                earlier)


def _earlier_indices(k: int, spec: DatasetSpec) -> list[int]:
    """Frames fused into frame ``k``'s reconstruction: the previous
    ``reconstruction.fusion.frames`` of its trajectory, most recent first."""
    n = int(spec.reconstruction.fusion.frames)
    return list(range(k - 1, max(-1, k - 1 - n), -1))


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
def summarize_dataset(store, dataset: str, spec: DatasetSpec | CaptureSpec,
                      outcomes: list[Outcome]) -> RunSummary:
    """The run summary: counts, per-geometry table and per-stage seconds.

    Returns
    -------
    dict — :func:`~sim2radar.tasks.common.summarize`'s (``counts``: worlds by status,
    ``frame_counts``: frames by status, ``outcomes``: the worlds) and ``geometry`` -> {``frames``, ``points_per_frame``, ``labels_per_frame``,
    ``gt_doors_per_frame``, ``frac_frames_with_label``, ``frac_gt_doors_with_points``,
    ``label_recall`` / ``label_precision`` (labels vs ground-truth doors in the radar's view at
    3D IoU >= 0.3; 1 for ground_truth by construction; GT doors outside the camera's narrower
    view count as misses for ``reconstructed``)},
    ``seconds_per_frame`` -> {stage: mean [s]}, ``comparison`` (both geometries:
    ``points_ratio``, ``chamfer_m`` means and per frame).
    """
    from sim2radar.evaluate.dataset import finite_mean, geometry_metrics, stage_seconds

    frames = [f for o in outcomes for f in o.parts]
    extra: dict[str, Any] = {"frame_counts": count_statuses(frames),
                             "geometry": geometry_metrics(frames, spec.geometries),
                             "seconds_per_frame": stage_seconds(frames)}
    comp = {f.id: f.measured["comparison"] for f in frames if f.measured.get("comparison")}
    if comp:
        extra["comparison"] = {
            "points_ratio": finite_mean(c["points_ratio"] for c in comp.values()),
            "chamfer_m": finite_mean(c["chamfer_m"] for c in comp.values()),
            "frames": comp,
        }
    return summarize(store, dataset, outcomes, **extra)


# ---------------------------------------------------------------------------------------------
# OpenPCDet export
# ---------------------------------------------------------------------------------------------
def export_openpcdet(store, outcomes: list[Outcome], export_dir: str | os.PathLike,
                     geometry: str, **options: Any) -> dict[str, Any]:
    """Write the frames of one geometry that the outcomes made (those whose artifact exists)
    in OpenPCDet's custom layout: :func:`sim2radar.factory.export.export_frames` (its
    ``options``: ``seed``, ``label_range_m``, ``with_doppler``, ``splits``, ``metadata``)."""
    st = open_store(store)
    frames = (read_dataset_frame(st, f.artifacts[f"dataset_frames/{geometry}"])
              for o in outcomes for f in o.parts
              if holds_frame(f, geometry))
    return export_frames(frames, export_dir, geometry, **options)


def holds_frame(frame: Outcome, geometry: str) -> bool:
    """The frame outcome has a ``dataset_frames`` artifact in ``geometry`` (a frame that failed
    in a geometry lists no artifact of it)."""
    return f"dataset_frames/{geometry}" in frame.artifacts


def outcomes_from_manifest(store, dataset: str) -> list[Outcome]:
    """The world outcomes of a finished dataset, rebuilt from its manifest (frame rows
    ``world_<seed>_f<k>`` with ``dataset_frames/<geometry>`` artifacts): what
    :func:`export_openpcdet` needs to export a dataset of an earlier run. Geometries whose
    artifact is missing from the store are left out of each frame."""
    st = open_store(store)
    rows = st.manifest(dataset).rows()
    if not rows:
        raise ValueError(f"store {st.root}: dataset {dataset!r} has no manifest rows; "
                         f"known datasets: {st.manifests()}")
    worlds: dict[str, Outcome] = {}
    for r in rows:
        m = FRAME_ROW.match(r["scene_id"])
        if m is None or r["status"] == "failed":
            continue
        o = worlds.setdefault(m.group(1), Outcome(m.group(1), "skipped"))
        fo = Outcome(r["scene_id"], r["status"], index=int(m.group(2)),
                     artifacts=dict(r["artifacts"]))
        for name, key in r["artifacts"].items():
            if name.startswith("dataset_frames/") and not st.exists("dataset_frames", key):
                del fo.artifacts[name]
        o.parts.append(fo)
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
    frames = [f for o in outcomes for f in o.parts if holds_frame(f, geometry)]
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


def world_bev_pngs(store, outcomes: list[Outcome], png_dir: str | os.PathLike,
                   spec: DatasetSpec | CaptureSpec) -> list[str]:
    """One bird's-eye-view PNG per world (or capture scene) and geometry
    (:func:`sim2radar.visualize.frames_bev_png`): every frame's radar points and labels in the
    first frame's radar frame."""
    from sim2radar.visualize import frames_bev_png

    st = open_store(store)
    out = []
    for o in outcomes:
        for g in spec.geometries:
            dfs = [read_dataset_frame(st, f.artifacts[f"dataset_frames/{g}"])
                   for f in o.parts if holds_frame(f, g)]
            if dfs:
                path = Path(png_dir) / f"{o.id}_{_TAG[g]}.png"
                out.append(str(frames_bev_png(dfs, path, class_name=spec.class_name,
                                              title=f"{o.id} [{g}]")))
    return out


def export_all(store, outcomes, export_dir, spec: DatasetSpec | CaptureSpec, *,
               splits: dict[str, list[str]] | None = None,
               with_doppler: bool = False, domain: str | None = None) -> dict[str, Any]:
    """Export every geometry of the run: straight into ``export_dir`` for one geometry, into
    ``export_dir/<geometry>`` for ``both``; ``domain`` labels the export (default: simulated)."""
    opts = {"seed": spec.seed, "label_range_m": spec.export_label_range_m, "splits": splits,
            "with_doppler": with_doppler}
    if len(spec.geometries) == 1:
        g = spec.geometries[0]
        return {g: export_openpcdet(store, outcomes, export_dir, g, **opts,
                                    metadata=dataset_metadata(spec, g, domain))}
    return {g: export_openpcdet(store, outcomes, Path(export_dir) / g, g, **opts,
                                metadata=dataset_metadata(spec, g, domain))
            for g in spec.geometries}
