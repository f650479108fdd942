"""Data types of procedural worlds: the world, its objects and doors, rig poses, rendered frames.

Frames and conventions
----------------------
* **World frame**: metres, z up, floor at z = 0. Corridors and walls are axis-aligned.
* **Rig frame** (:attr:`RigPose.rig_to_world`): x forward, y left, z up; origin on the floor
  under the sensors. The sensors' extrinsics relative to the rig live in
  :class:`~sim2radar.worlds.config.RigConfig`.
* **Camera frame**: OpenCV (x right, y down, z forward), as in :mod:`sim2radar.camera`; pixel
  centres at +0.5.
* **Radar frame**: x forward, y left, z up (OpenPCDet/KITTI-LiDAR), the frame the radar simulator
  and the detector use. **LiDAR frame**: the same axes, at the LiDAR's mount.
* **Boxes**: rows ``x y z dx dy dz heading`` (:data:`sim2radar.vocab.BOX_FIELDS`), z the box
  centre. A door box is the **doorway box**: the door frame's outer width (``dx``, along the
  wall) × its depth through the wall (``dy`` = wall thickness + the frame's 1 cm lips on both
  faces) × the frame's height from the floor (``dz``, leaf height + head), aligned with the
  wall and independent of the leaves' swing angle (closed, ajar and open doors of one doorway
  have the same box — the passage a navigating robot needs). Leaves swung open and handles lie
  partly outside it. Headings lie in [-pi/2, pi/2) (a box is unchanged by a half turn).
  (Stage version 1 used the tight box around frame, leaves at their swing angle and handles.)

Public API (``from sim2radar.worlds import ...``)
-------------------------------------------------
``generate_world(seed, config=WorldConfig()) -> World``
    One seed -> one world, byte-identical on every run.
``trajectory(world, n_frames, seed, rig=RigConfig()) -> list[RigPose]``
    Rig poses walking the corridors.
``render_frame(world, pose, rig=RigConfig(), ...) -> WorldFrame``
    Mitsuba render: RGB (path traced), depth, normals, instance/semantic/material maps,
    LiDAR, door boxes with flags.

Instance ids index :attr:`World.objects` (and :attr:`World.meshes`, one object per mesh);
``-1`` means no surface.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from sim2radar.camera import CameraIntrinsics
from sim2radar.mesh import MaterialMesh

__all__ = [
    "Appearance",
    "WorldObject",
    "DoorSpec",
    "Space",
    "World",
    "RigPose",
    "WorldFrame",
    "NO_INSTANCE",
    "world_id_for",
]

#: Value of :attr:`WorldFrame.instance_id` where a pixel sees no surface.
NO_INSTANCE = -1


def world_id_for(seed: int) -> str:
    """The id of the world of ``seed`` in tables, manifests and frame ids:
    ``world_<seed, 6 digits>``."""
    return f"world_{int(seed):06d}"


@dataclasses.dataclass(frozen=True)
class Appearance:
    """Optical appearance of an object for RGB rendering (not used by the radar).

    Attributes
    ----------
    base_color : tuple[float, float, float] — linear RGB reflectance in [0, 1].
    roughness : float — microfacet roughness in [0, 1] (0 mirror-like, 1 matte).
    metallic : float — 0 dielectric, 1 conductor (for painted metal usually 0).
    texture : str — procedural texture kind: ``plain``, ``noise``, ``tiles``, ``grain``,
        ``brushed``, ``speckle``.
    texture_scale_m : float [m] — size of one texture period (tile edge, grain spacing).
    texture_contrast : float — relative brightness modulation of the texture in [0, 1].
    emission : float — radiance of an emitter (ceiling light panels), 0 for ordinary surfaces.
    texture_seed : int — seed of the procedural texture image.
    """

    base_color: tuple[float, float, float]
    roughness: float = 0.6
    metallic: float = 0.0
    texture: str = "plain"
    texture_scale_m: float = 0.5
    texture_contrast: float = 0.0
    emission: float = 0.0
    texture_seed: int = 0

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class WorldObject:
    """One row of the world's object table; ``World.objects[i]`` describes ``World.meshes[i]``.

    Attributes
    ----------
    instance_id : int — index into ``World.objects`` / ``World.meshes``.
    name : str — unique name, e.g. ``door_2_leaf_0``.
    semantic : str — a class from :data:`sim2radar.vocab.SEMANTIC_CLASSES`.
    material : str — a class from :data:`sim2radar.vocab.MATERIAL_CLASSES`.
    kind : str — finer object kind (``wall``, ``door_leaf``, ``door_frame``, ``door_handle``,
        ``cabinet``, ``radiator``, ``bin``, ``light``, ...).
    door_index : int — index into ``World.doors`` for door parts, else -1.
    space_index : int — index into ``World.spaces`` the object belongs to, -1 if shared.
    appearance : Appearance
    """

    instance_id: int
    name: str
    semantic: str
    material: str
    kind: str
    door_index: int
    space_index: int
    appearance: Appearance


@dataclasses.dataclass(frozen=True)
class DoorSpec:
    """One door (single or double) in a wall.

    Attributes
    ----------
    index : int — position in ``World.doors``.
    kind : str — ``single`` or ``double``.
    state : str — ``closed``, ``ajar`` or ``open``.
    swing_deg : tuple[float, ...] — opening angle of each leaf [deg] (0 = closed).
    width_m, height_m : float [m] — clear opening (between the frame's jambs / under its head).
    center_world : (3,) tuple [m] — centre of the opening on the floor (z = 0) in the wall's
        mid-plane.
    wall_axis : str — ``x`` if the wall runs along world x, else ``y``.
    box_world : (7,) tuple — ``x y z dx dy dz heading`` of the doorway box (see module doc).
    leads_to : int — index of the space behind the door (a room), -1 if none.
    leaf_material : str — material of the leaves (the door's radar-relevant material).
    """

    index: int
    kind: str
    state: str
    swing_deg: tuple[float, ...]
    width_m: float
    height_m: float
    center_world: tuple[float, float, float]
    wall_axis: str
    box_world: tuple[float, ...]
    leads_to: int
    leaf_material: str


@dataclasses.dataclass(frozen=True)
class Space:
    """A free-space rectangle: a corridor or a room.

    Attributes
    ----------
    index : int
    kind : str — ``corridor`` or ``room``.
    rect_m : (4,) tuple [m] — ``x0, x1, y0, y1`` of the free floor (walls lie outside it).
    axis : str — for corridors, the direction of travel (``x`` or ``y``); rooms ``""``.
    """

    index: int
    kind: str
    rect_m: tuple[float, float, float, float]
    axis: str = ""

    @property
    def size_m(self) -> tuple[float, float]:
        x0, x1, y0, y1 = self.rect_m
        return x1 - x0, y1 - y0


@dataclasses.dataclass(frozen=True, eq=False)
class World:
    """A generated indoor world.

    Attributes
    ----------
    seed : int
    config : WorldConfig — the resolved configuration it was generated from.
    layout : str — ``straight``, ``t_junction`` or ``l_turn``.
    ceiling_height_m : float [m]
    spaces : tuple[Space, ...] — corridors first (the main corridor is ``spaces[0]``), then rooms.
    meshes : tuple[MaterialMesh, ...] — world-frame geometry, one material each; ``meshes[i]``
        is described by ``objects[i]``.
    objects : tuple[WorldObject, ...]
    doors : tuple[DoorSpec, ...]
    path_world : (P, 2) float64 [m] — the corridor centre-line polyline trajectories follow.
    """

    seed: int
    config: Any
    layout: str
    ceiling_height_m: float
    spaces: tuple[Space, ...]
    meshes: tuple[MaterialMesh, ...]
    objects: tuple[WorldObject, ...]
    doors: tuple[DoorSpec, ...]
    path_world: np.ndarray

    @property
    def door_boxes_world(self) -> np.ndarray:
        """(M, 7) float64 — door boxes in the world frame (layout ``vocab.BOX_FIELDS``)."""
        if not self.doors:
            return np.zeros((0, 7))
        return np.array([d.box_world for d in self.doors], dtype=np.float64)

    def objects_table(self) -> dict[str, list]:
        """Column-wise object table (instance_id, name, semantic, material, kind, door_index,
        space_index), ready for a DataFrame or a Parquet table."""
        cols = ["instance_id", "name", "semantic", "material", "kind", "door_index", "space_index"]
        return {c: [getattr(o, c) for o in self.objects] for c in cols}

    def describe(self) -> dict[str, Any]:
        """A JSON-able summary of the layout (sizes, counts, door states)."""
        return {
            "seed": self.seed,
            "layout": self.layout,
            "ceiling_height_m": self.ceiling_height_m,
            "spaces": [dataclasses.asdict(s) for s in self.spaces],
            "doors": [dataclasses.asdict(d) for d in self.doors],
            "n_meshes": len(self.meshes),
            "n_triangles": int(sum(len(m.faces) for m in self.meshes)),
        }


@dataclasses.dataclass(frozen=True, eq=False)
class RigPose:
    """Pose of the sensor rig.

    Attributes
    ----------
    rig_to_world : (4, 4) float64 — rig frame (x forward, y left, z up, origin on the floor)
        to world.
    index : int — frame index along the trajectory.
    """

    rig_to_world: np.ndarray
    index: int = 0


@dataclasses.dataclass(frozen=True, eq=False)
class WorldFrame:
    """One rendered frame with its ground truth.

    Attributes
    ----------
    rgb : (H, W, 3) uint8 — sRGB image, path traced.
    depth_m : (H, W) float32 [m] — z-depth along the optical axis at each pixel centre; 0 where
        the primary ray hits nothing.
    normals : (H, W, 3) float32 — unit geometric surface normal in the camera frame, facing the
        camera; 0 where no surface.
    instance_id : (H, W) int32 — index into ``World.objects``; -1 (:data:`NO_INSTANCE`) where no
        surface.
    semantic_id : (H, W) uint8 — index into ``vocab.SEMANTIC_CLASSES`` (0 = none).
    material_id : (H, W) uint8 — index into ``vocab.MATERIAL_CLASSES`` (0 = none).
    lidar_points : (N, 3) float32 [m] — LiDAR returns in the **camera** frame (the full 360°
        sweep; points behind the camera have z < 0). ``lidar_to_camera`` maps the LiDAR's own
        frame to the camera frame.
    lidar_ring : (N,) uint8 — beam index of each return (0 = lowest beam).
    intrinsics : CameraIntrinsics
    camera_to_world, radar_to_world, lidar_to_world, rig_to_world : (4, 4) float64
    lidar_to_camera : (4, 4) float64
    door_boxes_world : (M, 7) float64 — one row per ``World.doors`` entry.
    door_boxes_radar : (M, 7) float64 — the same boxes in the radar frame.
    door_visible : (M,) bool — at least ``RigConfig.min_visible_pixels`` door pixels in the
        camera image.
    door_visible_pixels : (M,) int32 — number of pixels of the door's parts in the image.
    door_in_fov : (M,) bool — box centre inside the radar's azimuth and elevation field of view.
    door_in_range : (M,) bool — box centre within the radar's maximum range.
    seed : int — the world seed.
    frame_index : int
    timings_s : dict[str, float] — render times [s]: ``scene_s`` (Mitsuba scene build, first
        frame of a world only), ``maps_s``, ``lidar_s``, ``rgb_s`` (of which ``path_trace_s``),
        and ``total_s`` (the whole call; the parts are nested, do not sum them).
    """

    rgb: np.ndarray
    depth_m: np.ndarray
    normals: np.ndarray
    instance_id: np.ndarray
    semantic_id: np.ndarray
    material_id: np.ndarray
    lidar_points: np.ndarray
    lidar_ring: np.ndarray
    intrinsics: CameraIntrinsics
    camera_to_world: np.ndarray
    radar_to_world: np.ndarray
    lidar_to_world: np.ndarray
    rig_to_world: np.ndarray
    lidar_to_camera: np.ndarray
    door_boxes_world: np.ndarray
    door_boxes_radar: np.ndarray
    door_visible: np.ndarray
    door_visible_pixels: np.ndarray
    door_in_fov: np.ndarray
    door_in_range: np.ndarray
    seed: int
    frame_index: int
    timings_s: dict = dataclasses.field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.depth_m.shape[0]), int(self.depth_m.shape[1])

    @property
    def rig_calibration(self) -> dict[str, Any]:
        """The camera's calibration on its rig, as a real rig knows it: ``up_cam`` (3,) — the
        rig's up (gravity, the rig stands level on the floor) in the camera frame — and
        ``camera_height_m`` — the camera's height above the rig's floor point [m]. From the
        camera-to-rig extrinsic only (not from the pose in the world); keyword arguments of
        :class:`sim2radar.reconstruct.FrameInput`."""
        cam_in_rig = np.linalg.inv(self.rig_to_world) @ self.camera_to_world
        return {"up_cam": cam_in_rig[:3, :3].T @ np.array([0.0, 0.0, 1.0]),
                "camera_height_m": float(cam_in_rig[2, 3])}
