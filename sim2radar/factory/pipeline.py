"""One world frame -> one radar frame with door labels, for each geometry of the procedural
path (no store, no Prefect; ``tasks/dataset.py`` adds caching and I/O).

* :func:`ground_truth_frame` — the radar on the world's own meshes at the frame's
  ``radar_to_world``, moving along its heading at the spec's ``motion`` (a speed drawn per
  frame, :func:`~sim2radar.factory.seeds.frame_speed`); labels are the ground-truth doors the radar sees
  (:func:`ground_truth_labels`: at least ``labels.min_visibility`` of the doorway unoccluded,
  in FOV and range).
* :func:`reconstructed_frame` — the paper's pipeline: meshes reconstructed from the frame's RGB
  + LiDAR (:func:`world_frame_input`; the reconstruction's steps run in ``tasks/steps.py``)
  moved into the rig's radar frame (``inv(radar_to_world) @ camera_to_world``) and
  simulated with the rig moving as for the ground truth (:func:`rig_motion`: the same speed
  per frame); labels are the reconstructed door
  boxes the radar sees on the reconstructed geometry (the same visibility rule), the paper's
  pre-training pseudo-labels. The ground-truth doors the radar sees are stored alongside.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from sim2radar.factory.frames import DatasetFrame, points_near_boxes
from sim2radar.factory.labels import radar_visibility, scene_ray_caster

__all__ = ["frame_id_for", "with_material", "rig_motion", "ground_truth_labels", "ground_truth_frame",
           "world_frame_input", "reconstructed_frame", "world_surface_offsets",
           "render_seconds", "world_radar_frames"]


def frame_id_for(seed: int, frame_index: int) -> str:
    """``world_<seed 6 digits>_f<index 3 digits>`` (OpenPCDet frame id and manifest row)."""
    from sim2radar.worlds import world_id_for

    return f"{world_id_for(seed)}_f{int(frame_index):03d}"


def with_material(meshes, material: str | None):
    """The meshes, every one made of ``material`` (None: unchanged; the one-material
    ablation)."""
    if material is None:
        return meshes
    return [dataclasses.replace(m, material=material) for m in meshes]


def render_seconds(frame) -> float:
    """Render wall time of a world frame [s] (``total_s`` of the renderer's timings)."""
    t = frame.timings_s or {}
    return float(t.get("total_s", t.get("render_s", 0.0)))


def ground_truth_labels(frame, world_scene, spec):
    """Ground-truth doors the radar sees (on the world's meshes): boxes (radar frame), their
    door indices and visibilities."""
    from sim2radar.worlds import radar_view

    boxes = np.asarray(frame.door_boxes_radar, np.float32).reshape(-1, 7)
    vis = radar_visibility(boxes, scene_ray_caster(world_scene, frame.radar_to_world),
                           radar_view(spec.rig), spec.labels)
    idx = np.flatnonzero(vis >= spec.labels.min_visibility).astype(np.int32)
    return boxes[idx], idx, vis[idx].astype(np.float32)


def rig_motion(frame, spec) -> tuple[float, np.ndarray | None]:
    """The rig's speed [m/s] while ``frame`` is taken (drawn per frame from the spec's
    ``motion``, :func:`~sim2radar.factory.seeds.frame_speed`: the same for every geometry and
    radar of the frame) and its velocity in the radar frame [m/s] (None at rest)."""
    from sim2radar.factory.seeds import frame_speed
    from sim2radar.worlds import rig_velocity

    speed = (frame_speed(spec.motion.speed_mps, spec.seed, frame.seed, frame.frame_index)
             if spec.moving else 0.0)
    return speed, (rig_velocity(frame.radar_to_world, speed) if speed > 0 else None)


def ground_truth_frame(frame, world_id: str, world_scene, spec, radar_seed: int) -> DatasetFrame:
    """The radar on the world's meshes (``world_scene``, a RadarScene in the world frame) at the
    frame's radar pose, labelled with the ground-truth doors it sees."""
    from sim2radar.radar import simulate_scene_frame

    speed, velocity = rig_motion(frame, spec)
    t0 = time.perf_counter()
    rf = simulate_scene_frame(world_scene, spec.radar, frame.radar_to_world, seed=radar_seed,
                              velocity_mps=velocity)
    sim_s = time.perf_counter() - t0
    gt, idx, vis = ground_truth_labels(frame, world_scene, spec)
    return DatasetFrame(
        frame_id=frame_id_for(frame.seed, frame.frame_index), world_id=world_id,
        seed=frame.seed, frame_index=frame.frame_index, geometry="ground_truth",
        radar_to_world=frame.radar_to_world, points=rf.points, doppler_mps=rf.doppler_mps,
        boxes=gt, box_labels=(spec.class_name,) * len(gt), label_visibility=vis,
        gt_boxes=gt, gt_door_index=idx, gt_points_near=points_near_boxes(rf.points, gt),
        gt_visibility=vis, n_triangles=world_scene.n_triangles,
        timings_s={"render": render_seconds(frame), "simulate": sim_s},
        stats={"radar": rf.stats, "radar_seed": radar_seed, "rig_speed_mps": speed},
        surface_offset_m=world_surface_offsets(rf.points, world_scene, frame),
    )


def world_surface_offsets(points, world_scene, frame) -> np.ndarray:
    """(N,) float32 — each radar point's range minus the first surface of the world's
    meshes (``world_scene``, a RadarScene in the world frame) along its ray from the frame's
    true radar pose [m] (:func:`sim2radar.evaluate.fidelity.surface_offsets`)."""
    from sim2radar.evaluate.fidelity import surface_offsets

    return surface_offsets(points, scene_ray_caster(world_scene, frame.radar_to_world))


def world_frame_input(frame):
    """A world frame's RGB + LiDAR as the reconstruction's input, with the rig's calibration
    (camera pitch and height on the level rig) as a real rig's would come
    (``reconstruction.rig_calibration: false`` ignores it)."""
    from sim2radar.reconstruct import FrameInput

    return FrameInput(frame.rgb, frame.intrinsics, frame.lidar_points,
                      name=frame_id_for(frame.seed, frame.frame_index), **frame.rig_calibration)


def reconstructed_frame(frame, world_id: str, world_scene, spec, radar_seed: int, *, meshes,
                        door_boxes, reconstruct_s: float, stats: dict) -> DatasetFrame:
    """The radar on reconstructed ``meshes`` (the rig's radar frame), labelled with the
    reconstructed ``door_boxes`` (radar frame) it sees on them; the ground-truth doors it sees
    on the world (``world_scene``) are stored for scoring. ``stats`` (reconstruction
    diagnostics, keys) go into the frame's stats.

    Raises
    ------
    ValueError — no meshes (nothing for the radar).
    """
    from sim2radar.radar import RadarScene, simulate_scene_frame
    from sim2radar.worlds import radar_view

    fid = frame_id_for(frame.seed, frame.frame_index)
    if not meshes:
        raise ValueError(f"{fid}: reconstruction produced no meshes; nothing for the radar")
    boxes = np.asarray(door_boxes, np.float32).reshape(-1, 7)
    n_fitted = int(len(boxes))
    speed, velocity = rig_motion(frame, spec)
    t0 = time.perf_counter()
    radar_scene = RadarScene(with_material(meshes, spec.material_override))
    rf = simulate_scene_frame(radar_scene, spec.radar, None, seed=radar_seed,
                              velocity_mps=velocity)
    sim_s = time.perf_counter() - t0
    # the reconstructed doors the radar sees on the reconstructed geometry are the labels
    vis = radar_visibility(boxes, scene_ray_caster(radar_scene), radar_view(spec.rig), spec.labels)
    keep = vis >= spec.labels.min_visibility
    boxes, vis = boxes[keep], vis[keep].astype(np.float32)
    gt, idx, gt_vis = ground_truth_labels(frame, world_scene, spec)
    return DatasetFrame(
        frame_id=fid, world_id=world_id, seed=frame.seed, frame_index=frame.frame_index,
        geometry="reconstructed", radar_to_world=frame.radar_to_world, points=rf.points,
        doppler_mps=rf.doppler_mps, boxes=boxes, box_labels=(spec.class_name,) * len(boxes),
        label_visibility=vis, gt_boxes=gt, gt_door_index=idx,
        gt_points_near=points_near_boxes(rf.points, gt), gt_visibility=gt_vis,
        n_triangles=radar_scene.n_triangles,
        timings_s={"render": render_seconds(frame), "reconstruct": reconstruct_s,
                   "simulate": sim_s},
        stats={"radar": rf.stats, "radar_seed": radar_seed, "rig_speed_mps": speed, **stats,
               "n_boxes_fitted": n_fitted},
        surface_offset_m=world_surface_offsets(rf.points, world_scene, frame),
    )


def world_radar_frames(meshes, frames, radar, labels=None):
    """Radar point clouds of a world's frames on its ground-truth ``meshes`` (``sim2radar
    worlds generate --radar``): per frame the points (N, 4), the simulation seconds and the
    door boxes (radar frame) the radar sees (``labels``, default :class:`LabelConfig`; the
    radar's own FOV and range). Radar seeds: :func:`~sim2radar.factory.seeds.frame_seed` with
    run seed 0."""
    from sim2radar.factory.labels import LabelConfig
    from sim2radar.factory.seeds import frame_seed
    from sim2radar.radar import RadarScene, simulate_frame

    labels = labels or LabelConfig()
    scene = RadarScene(list(meshes))
    view = (radar.azimuth_fov_deg, radar.elevation_fov_deg, radar.max_range_m)
    points, seconds, boxes = [], [], []
    for f in frames:
        t0 = time.perf_counter()
        result = simulate_frame(scene, radar, f.radar_to_world,
                                seed=frame_seed(0, f.seed, f.frame_index))
        seconds.append(time.perf_counter() - t0)
        points.append(np.asarray(result.points, np.float32).reshape(-1, 4))
        vis = radar_visibility(f.door_boxes_radar, scene_ray_caster(scene, f.radar_to_world),
                               view, labels)
        boxes.append(f.door_boxes_radar[vis >= labels.min_visibility])
    return points, seconds, boxes
