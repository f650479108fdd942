"""Mitsuba rendering of a world from a rig pose: RGB, depth, normals, masks, LiDAR, door boxes.

* **RGB** is path traced (Mitsuba ``path`` integrator, ``RigConfig.spp`` samples per pixel,
  ``RigConfig.max_depth``) with the ceiling light panels as area emitters and a dim constant
  sky seen through windows; tone-mapped to sRGB uint8 with a fixed exposure.
* **Depth, normals, instance/semantic/material maps** come from casting exactly one primary ray
  per pixel centre (u, v) = (j + 0.5, i + 0.5) through the pinhole model of
  :mod:`sim2radar.camera` with ``scene.ray_intersect``: they are exact, not filtered.
* **LiDAR**: ``RigConfig.lidar_beams`` beams evenly spaced in elevation, a full 360° sweep in
  ``lidar_azimuth_step_deg`` steps, ray cast from the LiDAR's mount, returned in the camera frame.

Geometry is built in memory (``mi.Mesh``); the Mitsuba scene of a world is cached and reused
for all frames of that world. The variant comes from :func:`sim2radar.hardware.mitsuba_variant`.
"""

from __future__ import annotations

import math
import time
import weakref

import numpy as np

from sim2radar.boxes import boxes_to_frame
from sim2radar.camera import CameraIntrinsics
from sim2radar.hardware import ReleasedUnderLock, drjit_serial, mitsuba_variant, to_drjit
from sim2radar.vocab import material_id, semantic_id
from sim2radar.worlds.appearance import texture_image
from sim2radar.worlds.config import RigConfig, radar_view
from sim2radar.worlds.frame import NO_INSTANCE, RigPose, World, WorldFrame

__all__ = [
    "render_frame",
    "rig_extrinsics",
    "camera_rays",
    "cast_rays",
    "RENDER_VERSION",
]

#: Bump when rendering changes its output for the same world and pose (artifact keys).
RENDER_VERSION = 1
#: Radiance of the constant environment (outside, seen through windows).
_SKY_RADIANCE = 1.2
#: Exposure multiplier applied before the sRGB curve.
_EXPOSURE = 1.6

# camera axes (OpenCV: x right, y down, z forward) expressed in the rig frame (x fwd, y left, z up)
_CAM_IN_RIG = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _pose_matrix(rotation: np.ndarray, translation) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = translation
    return m


def rig_extrinsics(rig: RigConfig) -> dict[str, np.ndarray]:
    """Sensor-to-rig transforms, (4, 4) float64 each: ``camera``, ``radar``, ``lidar``.

    The camera looks along the rig's +x, pitched down by ``camera_pitch_deg``; radar and LiDAR
    are level and face +x.
    """
    p = math.radians(rig.camera_pitch_deg)
    # pitch down = rotation about the rig's +y axis by +p (x tilts towards -z)
    pitch = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    return {
        "camera": _pose_matrix(pitch @ _CAM_IN_RIG, rig.camera_position_m),
        "radar": _pose_matrix(np.eye(3), rig.radar_position_m),
        "lidar": _pose_matrix(np.eye(3), rig.lidar_position_m),
    }


def camera_rays(intrinsics: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Unnormalised camera-frame directions through every pixel centre.

    Returns
    -------
    dirs : (H*W, 3) float64 — (x, y, 1) per pixel, row-major.
    norm : (H*W,) float64 — their lengths (z-depth = ray distance / norm).
    """
    k = intrinsics
    u = (np.arange(k.width) + 0.5 - k.cx) / k.fx
    v = (np.arange(k.height) + 0.5 - k.cy) / k.fy
    uu, vv = np.meshgrid(u, v)
    d = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
    return d, np.linalg.norm(d, axis=1)


class _WorldScene(ReleasedUnderLock):
    """A world's Mitsuba scene and the look-up tables from Mitsuba's shape ids to the world's
    instance, semantic, material and door ids. It dies under :data:`DRJIT_LOCK` wherever the
    last reference goes (:class:`~sim2radar.hardware.ReleasedUnderLock`), so only this object,
    never its ``scene`` alone, is held outside a :func:`drjit_serial` call."""

    def __init__(self, scene, lut: np.ndarray, sem: np.ndarray, mat: np.ndarray,
                 door: np.ndarray) -> None:
        self.scene, self.lut, self.sem, self.mat, self.door = scene, lut, sem, mat, door


class _SceneCache:
    """The Mitsuba scene of the most recently rendered worlds (weakly keyed by World)."""

    def __init__(self) -> None:
        self._cache: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def get(self, world: World) -> _WorldScene:
        entry = self._cache.get(world)
        if entry is None:
            entry = _build_scene(world)
            self._cache[world] = entry
        return entry


_SCENES = _SceneCache()


def _bsdf(mi, app, material: str):
    if material == "glass":
        return mi.load_dict({"type": "thindielectric", "int_ior": 1.5})
    tex = texture_image(app)
    refl = ({"type": "rgb", "value": list(app.base_color)} if tex is None else
            {"type": "bitmap", "bitmap": mi.Bitmap(tex), "wrap_mode": "repeat", "raw": True})
    if app.metallic >= 0.5:
        return mi.load_dict({"type": "roughconductor", "material": "none",
                             "specular_reflectance": refl,
                             "alpha": max(0.05, app.roughness**2)})
    if app.roughness >= 0.7:
        return mi.load_dict({"type": "diffuse", "reflectance": refl})
    # 'principled' rather than 'roughplastic': the latter precomputes tables (~0.1 s per load)
    return mi.load_dict({"type": "principled", "base_color": refl,
                         "roughness": max(0.05, app.roughness), "specular": 0.5})


def _mi_mesh(mi, dr, name: str, vertices: np.ndarray, faces: np.ndarray, bsdf, scale_m: float,
             emitter=None):
    """Un-indexed triangle mesh with planar world-space UVs (dominant normal axis)."""
    tri = vertices[faces].reshape(-1, 3)  # (3F, 3)
    t = vertices[faces]
    n = np.abs(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
    axis = np.argmax(n, axis=1).repeat(3)
    uv = np.where(axis[:, None] == 0, tri[:, [1, 2]],
                  np.where(axis[:, None] == 1, tri[:, [0, 2]], tri[:, [0, 1]])) / scale_m
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    m = mi.Mesh(name, len(tri), len(faces), props=props, has_vertex_normals=False,
                has_vertex_texcoords=True)
    p = mi.traverse(m)
    p["vertex_positions"] = dr.ravel(to_drjit(mi.Point3f, tri.T, np.float32))
    p["faces"] = dr.ravel(to_drjit(mi.Vector3u, np.arange(len(tri)).reshape(-1, 3).T, np.uint32))
    p["vertex_texcoords"] = dr.ravel(to_drjit(mi.Point2f, uv.T, np.float32))
    p.update()
    return m


@drjit_serial
def _build_scene(world: World):
    mitsuba_variant()
    import drjit as dr
    import mitsuba as mi

    desc = {"type": "scene",
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": _SKY_RADIANCE}}}
    for i, (mesh, obj) in enumerate(zip(world.meshes, world.objects, strict=True)):
        app = obj.appearance
        emitter = None
        if app.emission > 0:
            emitter = mi.load_dict({"type": "area", "radiance": {"type": "rgb",
                                                                  "value": app.emission}})
        desc[f"i{i}"] = _mi_mesh(mi, dr, f"i{i}", mesh.vertices.astype(np.float64),
                                 mesh.faces, _bsdf(mi, app, obj.material),
                                 app.texture_scale_m, emitter)
    scene = mi.load_dict(desc)
    # map Mitsuba shape registry ids -> our instance ids
    ids = np.asarray(dr.reinterpret_array(mi.UInt32, scene.shapes_dr()), dtype=np.int64)
    names = [s.id() for s in scene.shapes()]
    lut = np.full(int(ids.max()) + 1, NO_INSTANCE, dtype=np.int32)
    for sid, name in zip(ids, names, strict=True):
        lut[sid] = int(name[1:])
    sem = np.array([semantic_id(o.semantic) for o in world.objects], dtype=np.uint8)
    mat = np.array([material_id(o.material) for o in world.objects], dtype=np.uint8)
    door = np.array([o.door_index for o in world.objects], dtype=np.int32)
    return _WorldScene(scene, lut, sem, mat, door)


@drjit_serial
def cast_rays(world: World, origins: np.ndarray, directions: np.ndarray) -> dict[str, np.ndarray]:
    """Cast rays into the world's Mitsuba scene.

    Parameters
    ----------
    origins : (N, 3) or (3,) float [m] — world frame.
    directions : (N, 3) float — world frame, unit length.

    Returns
    -------
    dict with ``t`` (N,) float64 distance [m] (inf on a miss), ``instance`` (N,) int32
    (-1 on a miss), ``normal`` (N, 3) float64 world-frame geometric normal (0 on a miss).
    """
    import drjit as dr
    import mitsuba as mi

    entry = _SCENES.get(world)
    scene, lut = entry.scene, entry.lut
    d = np.asarray(directions, dtype=np.float64)
    o = np.broadcast_to(np.asarray(origins, dtype=np.float64), d.shape)
    ray = mi.Ray3f(to_drjit(mi.Point3f, o.T, np.float32), to_drjit(mi.Vector3f, d.T, np.float32))
    si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.Minimal | mi.RayFlags.ShadingFrame,
                             coherent=True)
    valid = np.asarray(si.is_valid(), dtype=bool)
    t = np.where(valid, np.asarray(si.t, dtype=np.float64), np.inf)
    sid = np.asarray(dr.reinterpret_array(mi.UInt32, si.shape), dtype=np.int64)
    inst = np.where(valid, lut[np.clip(sid, 0, len(lut) - 1)], NO_INSTANCE).astype(np.int32)
    n = np.asarray(si.n, dtype=np.float64).reshape(3, -1).T
    n = np.where(valid[:, None], n, 0.0)
    return {"t": t, "instance": inst, "normal": n}


def _tonemap(linear: np.ndarray) -> np.ndarray:
    """Linear RGB -> sRGB uint8: fixed exposure, exponential shoulder, IEC 61966-2-1 curve."""
    x = np.maximum(np.nan_to_num(linear, nan=0.0), 0.0) * _EXPOSURE
    x = 1.0 - np.exp(-x)  # exponential shoulder: light panels saturate softly
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.clip(np.round(srgb * 255.0), 0, 255).astype(np.uint8)


def render_frame(
    world: World,
    pose: RigPose | np.ndarray,
    rig: RigConfig | None = None,
    *,
    rgb: bool = True,
    lidar: bool = True,
) -> WorldFrame:
    """Render one frame of ``world`` from rig ``pose``.

    Parameters
    ----------
    pose : RigPose or (4, 4) rig-to-world matrix.
    rig : RigConfig — camera, radar, LiDAR and rendering settings.
    rgb : bool — path trace the RGB image (else a black image; the exact maps are always made).
    lidar : bool — cast the LiDAR sweep (else no points).
    """
    rig = rig if rig is not None else RigConfig()
    if isinstance(pose, RigPose):
        rig_to_world, frame_index = np.asarray(pose.rig_to_world, np.float64), pose.index
    else:
        rig_to_world, frame_index = np.asarray(pose, np.float64), 0
    if rig_to_world.shape != (4, 4):
        raise ValueError(f"pose must be a (4, 4) rig-to-world matrix, got {rig_to_world.shape}")
    timings: dict[str, float] = {}
    t_start = t0 = time.perf_counter()
    entry = _SCENES.get(world)
    sem_lut, mat_lut, door_lut = entry.sem, entry.mat, entry.door
    timings["scene_s"] = time.perf_counter() - t0

    ext = rig_extrinsics(rig)
    cam_to_world = rig_to_world @ ext["camera"]
    radar_to_world = rig_to_world @ ext["radar"]
    lidar_to_world = rig_to_world @ ext["lidar"]
    k = CameraIntrinsics.from_fov(rig.width, rig.height, rig.hfov_deg)
    h, w = rig.height, rig.width

    # -- exact primary-ray maps
    t0 = time.perf_counter()
    d_cam, norm = camera_rays(k)
    d_world = (d_cam / norm[:, None]) @ cam_to_world[:3, :3].T
    hit = cast_rays(world, cam_to_world[:3, 3], d_world)
    valid = np.isfinite(hit["t"])
    depth = np.where(valid, hit["t"] / np.where(valid, norm, 1.0), 0.0).astype(np.float32)
    inst = hit["instance"]
    n_cam = hit["normal"] @ cam_to_world[:3, :3]
    facing = np.sum(n_cam * d_cam, axis=1) > 0
    n_cam[facing] *= -1
    safe = np.where(inst >= 0, inst, 0)
    semantic = np.where(inst >= 0, sem_lut[safe], 0).astype(np.uint8)
    material = np.where(inst >= 0, mat_lut[safe], 0).astype(np.uint8)
    door_of_pixel = np.where(inst >= 0, door_lut[safe], -1)
    timings["maps_s"] = time.perf_counter() - t0

    # -- LiDAR sweep
    t0 = time.perf_counter()
    lidar_to_camera = np.linalg.inv(cam_to_world) @ lidar_to_world
    if lidar:
        el = np.radians(np.linspace(*rig.lidar_elevation_deg, rig.lidar_beams))
        az = np.radians(np.arange(0.0, 360.0, rig.lidar_azimuth_step_deg))
        ee, aa = np.meshgrid(el, az, indexing="ij")
        dl = np.stack([np.cos(ee) * np.cos(aa), np.cos(ee) * np.sin(aa), np.sin(ee)], -1)
        dl = dl.reshape(-1, 3)
        ring = np.repeat(np.arange(rig.lidar_beams, dtype=np.uint8), len(az))
        lh = cast_rays(world, lidar_to_world[:3, 3], dl @ lidar_to_world[:3, :3].T)
        keep = lh["t"] <= rig.lidar_max_range_m
        rng_m = lh["t"][keep]
        if rig.lidar_range_noise_m > 0:
            noise_rng = np.random.default_rng([world.seed, frame_index, 99])
            rng_m = rng_m + noise_rng.normal(0.0, rig.lidar_range_noise_m, rng_m.shape)
        p_lidar = dl[keep] * rng_m[:, None]
        lidar_pts = (p_lidar @ lidar_to_camera[:3, :3].T + lidar_to_camera[:3, 3]).astype(
            np.float32)
        lidar_ring = ring[keep]
    else:
        lidar_pts = np.zeros((0, 3), np.float32)
        lidar_ring = np.zeros(0, np.uint8)
    timings["lidar_s"] = time.perf_counter() - t0

    # -- RGB
    t0 = time.perf_counter()
    if rgb:
        linear = _render_rgb(world, entry, cam_to_world, k, rig, frame_index)
        timings["path_trace_s"] = time.perf_counter() - t0
        if rig.denoise:
            points_w = cam_to_world[:3, 3] + d_world * np.where(valid, hit["t"], 0.0)[:, None]
            albedo = _albedo_map(world, points_w, hit["normal"], inst).reshape(h, w, 3)
            linear = _denoise(linear, albedo, n_cam.reshape(h, w, 3), inst.reshape(h, w))
        image = _tonemap(linear)
    else:
        image = np.zeros((h, w, 3), np.uint8)
    timings["rgb_s"] = time.perf_counter() - t0

    # -- door ground truth
    boxes_w = world.door_boxes_world
    boxes_r = boxes_to_frame(boxes_w, radar_to_world)
    m = len(world.doors)
    counts = np.bincount(door_of_pixel[door_of_pixel >= 0], minlength=m)[:m].astype(np.int32)
    visible = counts >= max(1, int(math.ceil(rig.min_visible_fraction * h * w)))
    c = boxes_r[:, :3]
    az_r = np.arctan2(c[:, 1], c[:, 0])
    el_r = np.arctan2(c[:, 2], np.hypot(c[:, 0], c[:, 1]))
    az_fov_deg, el_fov_deg, max_range_m = radar_view(rig)
    in_fov = ((c[:, 0] > 0) & (np.abs(az_r) <= math.radians(az_fov_deg) / 2)
              & (np.abs(el_r) <= math.radians(el_fov_deg) / 2))
    in_range = np.linalg.norm(c, axis=1) <= max_range_m
    timings["total_s"] = time.perf_counter() - t_start

    return WorldFrame(
        rgb=image,
        depth_m=depth.reshape(h, w),
        normals=np.where(valid[:, None], n_cam, 0.0).astype(np.float32).reshape(h, w, 3),
        instance_id=inst.reshape(h, w).astype(np.int32),
        semantic_id=semantic.reshape(h, w),
        material_id=material.reshape(h, w),
        lidar_points=lidar_pts,
        lidar_ring=lidar_ring,
        intrinsics=k,
        camera_to_world=cam_to_world,
        radar_to_world=radar_to_world,
        lidar_to_world=lidar_to_world,
        rig_to_world=rig_to_world,
        lidar_to_camera=lidar_to_camera,
        door_boxes_world=boxes_w,
        door_boxes_radar=boxes_r,
        door_visible=visible,
        door_visible_pixels=counts,
        door_in_fov=in_fov,
        door_in_range=in_range,
        seed=world.seed,
        frame_index=int(frame_index),
        timings_s=timings,
    )


@drjit_serial
def _render_rgb(world: World, entry: _WorldScene, cam_to_world: np.ndarray,
                k: CameraIntrinsics, rig: RigConfig, frame_index: int) -> np.ndarray:
    import mitsuba as mi

    # Mitsuba's camera frame is (x left, y up, z forward): flip OpenCV's x and y.
    to_world = cam_to_world @ np.diag([-1.0, -1.0, 1.0, 1.0])
    sensor = mi.load_dict({
        "type": "perspective",
        "fov": math.degrees(k.hfov_rad),
        "fov_axis": "x",
        "near_clip": 0.01,
        "to_world": mi.ScalarTransform4f(to_world.tolist()),
        "film": {"type": "hdrfilm", "width": k.width, "height": k.height,
                 "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": "independent", "sample_count": rig.spp},
    })
    integrator = mi.load_dict({"type": "path", "max_depth": rig.max_depth})
    seed = int(np.random.SeedSequence([world.seed, frame_index]).generate_state(1)[0])
    img = mi.render(entry.scene, sensor=sensor, integrator=integrator, spp=rig.spp, seed=seed)
    return np.asarray(img, dtype=np.float32)[..., :3]


_TEXTURES: dict[tuple, np.ndarray | None] = {}


def _texture(app) -> np.ndarray | None:
    key = (app.texture, app.texture_seed, app.base_color, app.texture_contrast)
    if key not in _TEXTURES:
        if len(_TEXTURES) > 4096:
            _TEXTURES.clear()
        _TEXTURES[key] = texture_image(app)
    return _TEXTURES[key]


def _albedo_map(world: World, points_w: np.ndarray, normals_w: np.ndarray,
                inst: np.ndarray) -> np.ndarray:
    """(N, 3) float32 surface reflectance at each primary hit (texture looked up with the same
    planar UVs as the renderer); 1 for glass, emitters and misses (not demodulated)."""
    out = np.ones((len(inst), 3), np.float32)
    axis = np.argmax(np.abs(normals_w), axis=1)
    for i in np.unique(inst[inst >= 0]):
        obj = world.objects[int(i)]
        app = obj.appearance
        sel = np.flatnonzero(inst == i)
        if obj.material == "glass" or app.emission > 0:
            continue
        tex = _texture(app)
        if tex is None:
            out[sel] = app.base_color
            continue
        p = points_w[sel] / app.texture_scale_m
        a = axis[sel]
        uu = np.where(a == 0, p[:, 1], p[:, 0])
        vv = np.where(a == 2, p[:, 1], p[:, 2])
        n = tex.shape[0]
        col = np.floor((uu % 1.0) * n).astype(int) % n
        row = np.floor((vv % 1.0) * n).astype(int) % n
        out[sel] = tex[row, col]
    return out


def _denoise(linear: np.ndarray, albedo: np.ndarray, normals_cam: np.ndarray,
             inst: np.ndarray) -> np.ndarray:
    """Edge-aware denoising of a low-spp render: divide out the albedo, smooth the irradiance
    with a joint bilateral filter guided by the exact normal and instance maps (edges between
    objects and creases are kept), multiply the albedo back."""
    import cv2

    alb = np.maximum(albedo, 0.02)
    irr = (linear / alb).astype(np.float32)
    hue = np.stack([(inst * 0.618034) % 1.0, (inst * 0.414214) % 1.0, (inst * 0.732051) % 1.0],
                   axis=-1)
    guide = (0.5 * normals_cam + 6.0 * np.where(inst[..., None] >= 0, hue, -1.0)).astype(
        np.float32)
    for _ in range(2):
        irr = cv2.ximgproc.jointBilateralFilter(guide, irr, 9, 0.25, 4.0)
    return irr * alb
