"""An analytic corridor frame: exact depth, normals, masks, materials, LiDAR and door boxes.

This is the reconstruction stage's own ground truth for tests and a fallback for the benchmark
when the procedural worlds (:mod:`sim2radar.worlds`) are not installed. Every surface is a
rectangle or an axis-aligned box, so each camera ray is intersected in closed form: the depth,
masks and LiDAR returns are exact, not rendered.

The returned :class:`SyntheticFrame` carries the same field names as ``sim2radar.worlds``'
``WorldFrame`` (``rgb``, ``depth_m``, ``normals``, ``instance_id``, ``semantic_id``,
``material_id``, ``lidar_points``, ``intrinsics``, ``camera_to_world``, ``radar_to_world``,
``door_boxes_world``, ``door_boxes_radar``) so oracle backends and scores accept either.

Frames
------
world : z up; the corridor runs along +x, floor at z = 0.
camera : OpenCV (x right, y down, z forward), :mod:`sim2radar.camera`.
radar : x forward, y left, z up (docs/design.md), at the rig, 0.1 m below the camera.
Boxes : ``x y z dx dy dz heading`` (``vocab.BOX_FIELDS``); for a door ``dx`` is its width
    (along the wall), ``dy`` = 0.17 m (a nominal 0.15 m wall behind the corridor's wall
    plane plus 1 cm frame lips, as the worlds' boxes span the wall), ``dz`` its height, heading the wall direction.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim2radar.boxes import boxes_to_frame
from sim2radar.camera import CameraIntrinsics
from sim2radar.mesh import MaterialMesh, box_mesh
from sim2radar.vocab import material_id, semantic_id

__all__ = ["SyntheticFrame", "corridor_frame", "CAM_FROM_LEVEL"]

#: Rotation taking vectors from a level radar-convention frame (x forward, y left, z up) to the
#: OpenCV camera frame (x right, y down, z forward).
CAM_FROM_LEVEL = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


@dataclasses.dataclass(frozen=True, eq=False)
class SyntheticFrame:
    """Ground truth of one analytic frame (field names follow ``sim2radar.worlds.WorldFrame``).

    Attributes
    ----------
    rgb : (H, W, 3) uint8
    depth_m : (H, W) float32 — z-depth [m], 0 where no surface.
    normals : (H, W, 3) float32 — unit surface normals, camera frame, facing the camera.
    instance_id : (H, W) int32 — index into ``objects``, -1 where no surface.
    semantic_id, material_id : (H, W) uint8 — indices into the vocabularies.
    lidar_points : (N, 3) float32 — LiDAR returns in the camera frame [m].
    intrinsics : CameraIntrinsics
    camera_to_world, radar_to_world : (4, 4) float64
    door_boxes_world, door_boxes_radar : (M, 7) float32 — ``vocab.BOX_FIELDS``.
    door_visible : (M,) bool — the door covers at least 0.2 % of the image (as the worlds' flag).
    meshes : list[MaterialMesh] — the scene in the world frame.
    objects : list[dict] — name, semantic, material per instance id.
    """

    rgb: np.ndarray
    depth_m: np.ndarray
    normals: np.ndarray
    instance_id: np.ndarray
    semantic_id: np.ndarray
    material_id: np.ndarray
    lidar_points: np.ndarray
    intrinsics: CameraIntrinsics
    camera_to_world: np.ndarray
    radar_to_world: np.ndarray
    door_boxes_world: np.ndarray
    door_boxes_radar: np.ndarray
    door_visible: np.ndarray
    meshes: list
    objects: list
    seed: int = 0
    frame_index: int = 0

    @property
    def rig_calibration(self) -> dict:
        """``up_cam`` and ``camera_height_m`` of the level camera above the floor z = 0 (as
        ``WorldFrame.rig_calibration``): keyword arguments of ``FrameInput``."""
        return {"up_cam": self.camera_to_world[:3, :3].T @ np.array([0.0, 0.0, 1.0]),
                "camera_height_m": float(self.camera_to_world[2, 3])}


@dataclasses.dataclass(frozen=True)
class _Quad:
    origin: np.ndarray  # (3,) world [m]
    edge_a: np.ndarray  # (3,)
    edge_b: np.ndarray  # (3,)
    instance: int


def _box_quads(center, size, instance) -> list[_Quad]:
    c = np.asarray(center, float)
    h = np.asarray(size, float) / 2
    quads = []
    for axis in range(3):
        o1, o2 = [(i) for i in range(3) if i != axis]
        for sign in (-1, 1):
            origin = c.copy()
            origin[axis] += sign * h[axis]
            origin[o1] -= h[o1]
            origin[o2] -= h[o2]
            ea = np.zeros(3)
            eb = np.zeros(3)
            ea[o1] = 2 * h[o1]
            eb[o2] = 2 * h[o2]
            quads.append(_Quad(origin, ea, eb, instance))
    return quads


def _cast(origins: np.ndarray, dirs: np.ndarray, quads: list[_Quad]):
    """Nearest hit of rays (N,3)+(N,3) against rectangles; returns t (N,), instance (N,), normal (N,3)."""
    n = len(dirs)
    best_t = np.full(n, np.inf)
    best_i = np.full(n, -1, dtype=np.int32)
    best_n = np.zeros((n, 3))
    for q in quads:
        normal = np.cross(q.edge_a, q.edge_b)
        normal /= np.linalg.norm(normal)
        denom = dirs @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((q.origin - origins) @ normal) / denom
        p = origins + t[:, None] * dirs - q.origin
        s = p @ q.edge_a / (q.edge_a @ q.edge_a)
        r = p @ q.edge_b / (q.edge_b @ q.edge_b)
        hit = (np.abs(denom) > 1e-9) & (t > 1e-6) & (s >= 0) & (s <= 1) & (r >= 0) & (r <= 1)
        better = hit & (t < best_t)
        best_t[better] = t[better]
        best_i[better] = q.instance
        best_n[better] = normal
    facing = np.sum(best_n * dirs, axis=1) > 0
    best_n[facing] *= -1
    return best_t, best_i, best_n


def _texture(hit_world: np.ndarray, inst: np.ndarray, materials: list[str],
             rng: np.random.Generator) -> np.ndarray:
    """Brightness modulation (H, W) by material, in world-space surface coordinates: tiles with
    dark grout for ceramic tile, low-frequency mottling for concrete, grain for wood."""
    out = np.ones(inst.shape)
    x, y, z = hit_world[..., 0], hit_world[..., 1], hit_world[..., 2]
    phase = rng.uniform(0, 2 * np.pi, 6)
    for i, mat in enumerate(materials):
        m = inst == i
        if not m.any():
            continue
        # surface coordinates: the two axes along which this surface extends most
        ext = np.array([np.ptp(c[m]) for c in (x, y, z)])
        a, b = (np.stack([x, y, z])[k] for k in np.argsort(ext)[::-1][:2])
        if mat == "ceramic_tile":
            fa, fb = (a / 0.4) % 1, (b / 0.4) % 1
            grout = np.minimum(np.minimum(fa, 1 - fa), np.minimum(fb, 1 - fb)) < 0.04
            out[m] = np.where(grout, 0.45, 1.0)[m]
        elif mat == "concrete":
            mott = sum(np.sin(2 * np.pi * (a * fa + b * fb) + ph) / (k + 1)
                       for k, (fa, fb, ph) in enumerate(zip(rng.uniform(0.5, 6, 8),
                                                            rng.uniform(0.5, 6, 8),
                                                            rng.uniform(0, 6.3, 8), strict=True)))
            out[m] = (1 + 0.08 * mott)[m]
        elif mat == "wood":
            out[m] = (1 + 0.25 * np.sin(2 * np.pi * (6 * a + 0.4 * np.sin(3 * b + phase[3]))))[m]
    return out


def _rot_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def corridor_frame(
    width: int = 96,
    height: int = 72,
    hfov_deg: float = 65.0,
    seed: int = 0,
    *,
    corridor_width_m: float | None = None,
    corridor_height_m: float = 2.7,
    corridor_length_m: float = 12.0,
    camera_height_m: float = 1.5,
    yaw_deg: float | None = None,
    n_doors: int | None = None,
    lidar_beams: int = 16,
) -> SyntheticFrame:
    """Render an analytic corridor with doors set slightly proud of the side walls.

    Parameters
    ----------
    width, height : int [px] — image size.
    hfov_deg : float [deg] — horizontal field of view.
    seed : int — draws the layout (corridor width, door positions, materials, colours).
    corridor_width_m, corridor_height_m, corridor_length_m : float [m]
    camera_height_m : float [m] — camera centre above the floor.
    yaw_deg : float [deg] — rig yaw about world z (random in ±8° when None).
    n_doors : int — number of doors (random 2–4 when None).
    lidar_beams : int — beams of the sparse LiDAR (elevation −15°..+15°, 0.4° azimuth steps).

    Returns
    -------
    SyntheticFrame
    """
    rng = np.random.default_rng(seed)
    cw = float(corridor_width_m or rng.uniform(1.8, 2.6))
    ch, cl = float(corridor_height_m), float(corridor_length_m)
    yaw = math.radians(rng.uniform(-8, 8) if yaw_deg is None else yaw_deg)
    y0 = rng.uniform(-0.2, 0.2) * cw
    n_doors = int(rng.integers(2, 5) if n_doors is None else n_doors)

    objects: list[dict] = []
    quads: list[_Quad] = []
    meshes: list[MaterialMesh] = []
    colours: list[np.ndarray] = []
    door_boxes = []
    door_instances: list[int] = []

    def add(name, sem, mat, colour, geom):
        idx = len(objects)
        objects.append({"name": name, "semantic": sem, "material": mat, "instance_id": idx})
        colours.append(np.asarray(colour, float))
        kind, args = geom
        if kind == "quad":
            o, a, b = (np.asarray(x, float) for x in args)
            quads.append(_Quad(o, a, b, idx))
            v = np.stack([o, o + a, o + a + b, o + b])
            meshes.append(MaterialMesh(v, [[0, 1, 2], [0, 2, 3]], material=mat, name=name,
                                       semantic=sem))
        else:
            center, size = args
            quads.extend(_box_quads(center, size, idx))
            meshes.append(box_mesh(center, size, material=mat, name=name, semantic=sem))
        return idx

    x0, x1 = -2.0, cl
    floor_mat = str(rng.choice(["ceramic_tile", "concrete"], p=[0.6, 0.4]))
    wall_mat = str(rng.choice(["plasterboard", "concrete"], p=[0.7, 0.3]))
    grey = rng.uniform(0.55, 0.85)
    add("floor", "floor", floor_mat, rng.uniform(0.35, 0.55) * rng.uniform(0.85, 1.0, 3),
        ("quad", ([x0, -cw / 2, 0], [x1 - x0, 0, 0], [0, cw, 0])))
    add("ceiling", "ceiling", "plasterboard", [0.9, 0.9, 0.88],
        ("quad", ([x0, -cw / 2, ch], [0, cw, 0], [x1 - x0, 0, 0])))
    wall_rgb = np.array([grey, grey * rng.uniform(0.92, 1.0), grey * rng.uniform(0.85, 1.0)])
    add("wall_left", "wall", wall_mat, wall_rgb,
        ("quad", ([x0, cw / 2, 0], [x1 - x0, 0, 0], [0, 0, ch])))
    add("wall_right", "wall", wall_mat, wall_rgb,
        ("quad", ([x0, -cw / 2, 0], [0, 0, ch], [x1 - x0, 0, 0])))
    add("wall_end", "wall", wall_mat, wall_rgb * 0.95,
        ("quad", ([x1, -cw / 2, 0], [0, cw, 0], [0, 0, ch])))

    slots = np.sort(rng.choice(np.arange(3.8, cl - 1.0, 1.5), size=n_doors, replace=False))
    for i, xc in enumerate(slots):
        side = 1 if (i % 2 == 0) == (rng.random() < 0.5) else -1
        dw, dh, thick = rng.uniform(0.85, 1.1), rng.uniform(1.95, 2.15), 0.06
        mat = str(rng.choice(["metal", "wood"], p=[0.7, 0.3]))
        colour = ([0.55, 0.33, 0.17] if mat == "wood" else
                  rng.choice([[0.25, 0.35, 0.6], [0.6, 0.15, 0.12], [0.3, 0.3, 0.32]]))
        yc = side * (cw / 2 - thick / 2 + 0.02)  # 4 cm proud of the wall plane
        center = [float(xc), yc, dh / 2]
        door_instances.append(
            add(f"door_{i}", "door", mat, colour, ("box", (center, [dw, thick, dh]))))
        # box convention of the worlds (the box spans the wall, dy = wall thickness + 2 cm): a
        # nominal 0.15 m wall behind the corridor's wall plane
        door_boxes.append([xc, side * (cw / 2 + 0.075), dh / 2, dw, 0.17, dh, 0.0])

    # one fire extinguisher (red, small) and one handrail (metal) on the walls
    ext_x = float(rng.uniform(2.2, 3.2))
    add("extinguisher", "fire_extinguisher", "metal", [0.8, 0.08, 0.06],
        ("box", ([ext_x, -cw / 2 + 0.1, 0.65], [0.18, 0.18, 0.5])))
    add("handrail", "handrail", "metal", [0.75, 0.75, 0.78],
        ("box", ([1.9, cw / 2 - 0.05, 0.95], [2.8, 0.05, 0.05])))

    intr = CameraIntrinsics.from_fov(width, height, hfov_deg)
    rig_to_world = np.eye(4)
    rig_to_world[:3, :3] = _rot_z(yaw)
    rig_to_world[:3, 3] = [0.0, y0, camera_height_m]
    camera_to_world = rig_to_world.copy()
    camera_to_world[:3, :3] = rig_to_world[:3, :3] @ CAM_FROM_LEVEL.T
    radar_to_world = rig_to_world.copy()
    radar_to_world[2, 3] -= 0.1

    # primary rays through pixel centres
    u = np.arange(width) + 0.5
    v = np.arange(height) + 0.5
    uu, vv = np.meshgrid(u, v)
    d_cam = np.stack([(uu - intr.cx) / intr.fx, (vv - intr.cy) / intr.fy, np.ones_like(uu)], -1)
    d_cam = d_cam.reshape(-1, 3)
    r_wc = camera_to_world[:3, :3]
    d_world = d_cam @ r_wc.T
    origin = np.broadcast_to(camera_to_world[:3, 3], d_world.shape)
    t, inst, n_world = _cast(origin, d_world, quads)
    valid = np.isfinite(t)
    depth = np.where(valid, t, 0.0).reshape(height, width).astype(np.float32)  # d_cam.z == 1
    inst = np.where(valid, inst, -1).reshape(height, width).astype(np.int32)
    normals = (n_world @ r_wc).reshape(height, width, 3).astype(np.float32)

    sem_lut = np.array([semantic_id(o["semantic"]) for o in objects] + [0], np.uint8)
    mat_lut = np.array([material_id(o["material"]) for o in objects] + [0], np.uint8)
    semantic = sem_lut[inst]
    material = mat_lut[inst]

    # appearance: base colour, Lambert shading from a head light, mild texture and sensor noise
    col = np.array(colours + [np.zeros(3)])[inst]
    shade = np.clip(-np.sum(normals * (d_cam / np.linalg.norm(d_cam, axis=1, keepdims=True))
                            .reshape(height, width, 3), axis=-1), 0, 1)
    light = 0.35 + 0.65 * shade / (1 + 0.03 * depth**2)
    hit = (origin + np.where(valid, t, 0)[:, None] * d_world).reshape(height, width, 3)
    tex = _texture(hit, inst, [o["material"] for o in objects], rng)
    tex = tex * (1 + 0.03 * rng.standard_normal((height, width)))
    rgb = np.clip(col * (light * tex)[..., None] * 255, 0, 255)
    rgb[inst < 0] = 0
    rgb = rgb.astype(np.uint8)

    # sparse LiDAR at the camera centre: beams in elevation, 0.4 deg azimuth steps
    el = np.radians(np.linspace(-15, 15, lidar_beams))
    az = np.radians(np.arange(-60, 60, 0.4))
    ee, aa = np.meshgrid(el, az, indexing="ij")
    d_level = np.stack([np.cos(ee) * np.cos(aa), np.cos(ee) * np.sin(aa), np.sin(ee)], -1)
    d_lc = d_level.reshape(-1, 3) @ CAM_FROM_LEVEL.T
    tl, _, _ = _cast(np.broadcast_to(camera_to_world[:3, 3], d_lc.shape), d_lc @ r_wc.T, quads)
    ok = np.isfinite(tl)
    lidar = (d_lc[ok] * tl[ok, None]).astype(np.float32)

    boxes_w = np.asarray(door_boxes, np.float32).reshape(-1, 7)
    return SyntheticFrame(
        rgb=rgb, depth_m=depth, normals=normals, instance_id=inst, semantic_id=semantic,
        material_id=material, lidar_points=lidar, intrinsics=intr,
        camera_to_world=camera_to_world, radar_to_world=radar_to_world,
        door_boxes_world=boxes_w, door_boxes_radar=boxes_to_frame(boxes_w, radar_to_world),
        door_visible=np.array([(inst == i).mean() >= 0.002 for i in door_instances], bool),
        meshes=meshes, objects=objects, seed=seed,
    )
