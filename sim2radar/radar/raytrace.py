"""Mitsuba 3 / Dr.Jit radar ray tracer: rays over the FOV -> bounces -> binned complex returns.

The scene (all meshes merged into one in-memory ``mi.Mesh``, one BVH) is built once per
:class:`RadarScene`; per-face material indices select the Fresnel table and the roughness
coefficient. Everything per ray is one vectorised Dr.Jit program (a Python loop runs over
bounces only); returns are scatter-added into flat per-cell accumulators on the device, and
only the small cube comes back to NumPy. The return model is documented in
:mod:`sim2radar.radar.returns`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence

import numpy as np

from sim2radar.em import get_material
from sim2radar.mesh import MaterialMesh
from sim2radar.radar.binning import Accumulator
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.returns import (
    FRESNEL_LUT_SIZE,
    GOLDEN,
    MIN_COS,
    diffuse_phase_seed,
    fresnel_lut,
    ray_grid,
)

__all__ = ["RadarScene", "TraceResult", "merge_meshes", "check_pose"]


def check_pose(pose: np.ndarray | None) -> np.ndarray:
    """Validate a (4, 4) radar-to-world transform (rigid); ``None`` -> identity."""
    if pose is None:
        return np.eye(4)
    m = np.asarray(pose, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"pose must be a (4, 4) radar-to-world matrix, got shape {m.shape}")
    if not np.isfinite(m).all():
        raise ValueError("pose contains NaN or inf")
    r = m[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or np.linalg.det(r) < 0:
        raise ValueError("pose[:3, :3] must be a rotation (orthonormal, det +1)")
    if not np.allclose(m[3], [0, 0, 0, 1]):
        raise ValueError("pose last row must be [0, 0, 0, 1]")
    return m


def merge_meshes(
    meshes: Sequence[MaterialMesh],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Concatenate meshes into one triangle soup with a per-face material index.

    Returns
    -------
    vertices : (V, 3) float32 [m]
    faces : (F, 3) uint32
    face_material : (F,) uint32 — index into ``materials``
    materials : list[str] — normalised material names
    """
    if isinstance(meshes, MaterialMesh):
        meshes = [meshes]
    meshes = list(meshes)
    if not meshes:
        raise ValueError("the scene has no meshes; pass a non-empty list of MaterialMesh")
    materials: list[str] = []
    verts, faces, mats = [], [], []
    offset = 0
    for i, mesh in enumerate(meshes):
        if not isinstance(mesh, MaterialMesh):
            raise TypeError(f"meshes[{i}] is {type(mesh).__name__}, expected MaterialMesh")
        try:
            name = get_material(mesh.material).name
        except KeyError as exc:
            raise ValueError(f"meshes[{i}] ({mesh.name or 'unnamed'}): {exc}") from None
        if name not in materials:
            materials.append(name)
        verts.append(mesh.vertices)
        faces.append(mesh.faces.astype(np.int64) + offset)
        mats.append(np.full(len(mesh.faces), materials.index(name), dtype=np.uint32))
        offset += len(mesh.vertices)
    f = np.concatenate(faces)
    if len(f) == 0:
        raise ValueError("the scene's meshes have no faces")
    return (
        np.concatenate(verts).astype(np.float32),
        f.astype(np.uint32),
        np.concatenate(mats),
        materials,
    )


@dataclasses.dataclass(frozen=True)
class TraceResult:
    """Accumulated returns of one frame plus counters and timings."""

    accumulator: Accumulator
    n_rays: int
    hits_per_bounce: tuple[int, ...]
    seconds: dict[str, float]


@dataclasses.dataclass
class _Prepared:
    """Per-(config, seed) device arrays: ray grid, solid angles, tables."""

    directions: object  # mi.Vector3f (N,), radar frame
    n_rays: int
    solid_angle: object  # mi.Float (N,)
    diffuse_u: object  # mi.Float (N,) in [0, 1)
    spacing_rad: float
    lut_re: object
    lut_im: object
    s_coef: object
    spec_coef: object


class RadarScene:
    """A scene built once for Mitsuba, simulated from many radar poses.

    Parameters
    ----------
    meshes : sequence of MaterialMesh
        Scene geometry in the world frame [m]; each mesh's material must be known to
        :mod:`sim2radar.em`.

    Examples
    --------
    >>> scene = RadarScene(meshes)
    >>> frames = [scene.simulate(radar, pose) for pose in poses]
    """

    def __init__(self, meshes: Sequence[MaterialMesh]) -> None:
        from sim2radar.hardware import mitsuba_variant

        t0 = time.perf_counter()
        self.variant = mitsuba_variant()
        if self.variant.startswith("scalar"):
            raise RuntimeError(
                "the radar ray tracer needs a vectorised Mitsuba variant (llvm_ad_rgb or "
                f"cuda_ad_rgb), but only {self.variant!r} works here: install libllvm19 "
                "(`apt-get install -y libllvm19`) or use a CUDA GPU"
            )
        import drjit as dr
        import mitsuba as mi

        self._mi, self._dr = mi, dr
        vertices, faces, face_material, self.materials = merge_meshes(meshes)
        self.n_triangles = int(len(faces))
        mesh = mi.Mesh(
            "radar_scene",
            vertex_count=len(vertices),
            face_count=len(faces),
            has_vertex_normals=False,
            has_vertex_texcoords=False,
        )
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(vertices.ravel())
        params["faces"] = mi.UInt32(faces.ravel())
        params.update()
        self._scene = mi.load_dict({"type": "scene", "mesh": mesh})
        self._face_material = mi.UInt32(face_material)
        self._prepared: dict[tuple[str, int | None], _Prepared] = {}
        self.build_seconds = time.perf_counter() - t0

    # ------------------------------------------------------------------------------------
    def _prepare(self, radar: RadarConfig, seed: int | None) -> _Prepared:
        key = (radar.content_hash(), seed)
        if key in self._prepared:
            return self._prepared[key]
        mi = self._mi
        directions, solid_angle, spacing = ray_grid(
            radar.azimuth_fov_rad,
            radar.elevation_fov_rad,
            math.radians(radar.ray_spacing_deg),
            seed=seed,
        )
        thickness = [radar.scattering.thickness_m(m) for m in self.materials]
        lut = fresnel_lut(self.materials, radar.center_frequency_hz, thickness_m=thickness)
        lut = lut.astype(np.complex64)
        s = np.array([radar.scattering.coefficient(m) for m in self.materials], dtype=np.float32)
        prep = _Prepared(
            directions=mi.Vector3f(
                *(mi.Float(directions[:, i].astype(np.float32)) for i in range(3))
            ),
            n_rays=len(directions),
            solid_angle=mi.Float(solid_angle.astype(np.float32)),
            diffuse_u=mi.Float(diffuse_phase_seed(len(directions), seed).astype(np.float32)),
            spacing_rad=spacing,
            lut_re=mi.Float(lut.real.ravel()),
            lut_im=mi.Float(lut.imag.ravel()),
            s_coef=mi.Float(s),
            spec_coef=mi.Float(np.sqrt(1.0 - s**2).astype(np.float32)),
        )
        if len(self._prepared) > 8:
            self._prepared.pop(next(iter(self._prepared)))
        self._prepared[key] = prep
        return prep

    def _primary_rays(self, prep: _Prepared, pose: np.ndarray):
        """Rotate the cached radar-frame grid by the pose (opaque scalars: no recompilation)."""
        mi, dr = self._mi, self._dr
        rot = [[dr.opaque(mi.Float, float(pose[i, j])) for j in range(3)] for i in range(3)]
        origin = mi.Point3f(*(dr.opaque(mi.Float, float(v)) for v in pose[:3, 3]))
        d = prep.directions
        d_world = mi.Vector3f(
            *(rot[i][0] * d.x + rot[i][1] * d.y + rot[i][2] * d.z for i in range(3))
        )
        return mi.Ray3f(origin, d_world), origin

    # ------------------------------------------------------------------------------------
    def simulate(
        self,
        radar: RadarConfig | str,
        pose: np.ndarray | None = None,
        *,
        return_cube: bool = False,
        seed: int | None = None,
    ):
        """Simulate one frame from ``pose``; see :func:`sim2radar.radar.simulate_frame`."""
        from sim2radar.radar.config import load_radar_config
        from sim2radar.radar.frame import simulate_scene_frame

        radar = radar if isinstance(radar, RadarConfig) else load_radar_config(radar)
        return simulate_scene_frame(self, radar, pose, return_cube=return_cube, seed=seed)

    def trace(
        self, radar: RadarConfig, pose: np.ndarray | None = None, *, seed: int | None = None
    ) -> TraceResult:
        """Trace one frame and return the accumulated (not yet detected) returns."""
        mi, dr = self._mi, self._dr
        pose = check_pose(pose)
        t0 = time.perf_counter()
        prep = self._prepare(radar, seed)
        ray, radar_pos = self._primary_rays(prep, pose)
        n = prep.n_rays
        t1 = time.perf_counter()

        wavenumber = 2.0 * math.pi / radar.wavelength_m
        inv_lambda = 1.0 / radar.wavelength_m
        lut_n = FRESNEL_LUT_SIZE
        n_r, n_a, n_e = radar.n_range_bins, radar.n_azimuth_bins, radar.n_elevation_bins
        n_cells = n_r * n_a * n_e
        inv_dr = 1.0 / radar.range_resolution_m
        az_half, el_half = 0.5 * radar.azimuth_fov_rad, 0.5 * radar.elevation_fov_rad
        inv_daz = n_a / radar.azimuth_fov_rad
        inv_del = n_e / radar.elevation_fov_rad
        # world -> radar rotation (R^T) as opaque scalars so a new pose reuses the kernel
        rt = [[dr.opaque(mi.Float, float(pose[j, i])) for j in range(3)] for i in range(3)]

        acc = [dr.zeros(mi.Float, n_cells) for _ in range(6)]
        hits = dr.zeros(mi.UInt32, radar.max_bounces)
        carry_re = dr.full(mi.Float, 1.0, n)
        carry_im = dr.zeros(mi.Float, n)
        path_in = dr.zeros(mi.Float, n)
        active = dr.full(mi.Bool, True, n)
        d_omega = prep.solid_angle
        prev_hit = mi.Point3f(radar_pos)

        for bounce in range(radar.max_bounces):
            si = self._scene.ray_intersect(ray, active)
            valid = active & si.is_valid()
            dr.scatter_reduce(dr.ReduceOp.Add, hits, mi.UInt32(1), mi.UInt32(bounce), valid)
            normal = si.n
            cos_in = -dr.dot(ray.d, normal)
            normal = dr.select(cos_in < 0, -normal, normal)
            cos_in = dr.abs(cos_in)
            hit = si.p
            # unfold the path from the true hit points: si.t is measured from the spawned
            # origin, which Mitsuba offsets ~(1+|p|) 1e-4 m off the surface (~0.1 lambda)
            path_in = path_in + dr.select(valid, dr.norm(hit - prev_hit), 0.0)
            to_radar = radar_pos - hit
            r_out = dr.norm(to_radar)
            u_out = to_radar / r_out
            cos_out = dr.dot(u_out, normal)
            visible = valid & (cos_out > 0)
            if bounce > 0:
                shadow = si.spawn_ray_to(radar_pos)
                visible &= ~self._scene.ray_test(shadow, visible)

            mat = dr.gather(mi.UInt32, self._face_material, si.prim_index, valid)
            x = dr.clip(cos_in, 0.0, 1.0) * (lut_n - 1)
            i0 = dr.minimum(mi.UInt32(dr.floor(x)), lut_n - 2)
            frac = x - mi.Float(i0)
            base = mat * lut_n + i0
            g_re = dr.lerp(
                dr.gather(mi.Float, prep.lut_re, base, valid),
                dr.gather(mi.Float, prep.lut_re, base + 1, valid),
                frac,
            )
            g_im = dr.lerp(
                dr.gather(mi.Float, prep.lut_im, base, valid),
                dr.gather(mi.Float, prep.lut_im, base + 1, valid),
                frac,
            )
            s_coef = dr.gather(mi.Float, prep.s_coef, mat, valid)
            spec = dr.gather(mi.Float, prep.spec_coef, mat, valid)
            cg_re = carry_re * g_re - carry_im * g_im  # C * Gamma
            cg_im = carry_re * g_im + carry_im * g_re

            path = path_in + r_out
            # e^{-jkL}: reduce to the fractional number of wavelengths first (float32 sincos
            # loses accuracy for |arguments| of 1e4 rad, i.e. paths of a few metres)
            cycles = path * inv_lambda
            phase = -2.0 * math.pi * (cycles - dr.floor(cycles))
            sin_p, cos_p = dr.sincos(phase)
            # physical-optics (specular) term with the Nyquist window
            ci = dr.maximum(cos_in, MIN_COS)
            grad = ray.d - u_out
            grad_t = grad - dr.dot(grad, normal) * normal
            dphi = wavenumber * dr.norm(grad_t) * path_in * prep.spacing_rad / ci
            xw = dr.clip((dphi - 0.5 * math.pi) / (0.5 * math.pi), 0.0, 1.0)
            window = dr.square(dr.cos(0.5 * math.pi * xw))
            amp_c = (
                inv_lambda * spec * d_omega * (cos_in + cos_out) / (2.0 * ci) * (path_in / r_out)
            ) * window
            z_re = cg_re * cos_p - cg_im * sin_p
            z_im = cg_re * sin_p + cg_im * cos_p
            a_re = -z_im * amp_c  # multiply by j
            a_im = z_re * amp_c
            # diffuse (Lambertian) term with a per-ray pseudo-random phase
            amp_d = s_coef * dr.sqrt(d_omega * dr.maximum(cos_out, 0.0) / math.pi) / r_out
            u = prep.diffuse_u + bounce * GOLDEN
            sin_d, cos_d = dr.sincos(phase - 2.0 * math.pi * (u - dr.floor(u)))
            a_re += (cg_re * cos_d - cg_im * sin_d) * amp_d
            a_im += (cg_re * sin_d + cg_im * cos_d) * amp_d

            # bin: range = half path, angles of the last hit seen from the radar
            q = hit - radar_pos
            qx = rt[0][0] * q.x + rt[0][1] * q.y + rt[0][2] * q.z
            qy = rt[1][0] * q.x + rt[1][1] * q.y + rt[1][2] * q.z
            qz = rt[2][0] * q.x + rt[2][1] * q.y + rt[2][2] * q.z
            az = dr.atan2(qy, qx)
            el = dr.atan2(qz, dr.sqrt(qx * qx + qy * qy))
            rng_m = 0.5 * path
            ir = mi.Int32(dr.floor(rng_m * inv_dr + 0.5))
            ia = mi.Int32(dr.floor((az + az_half) * inv_daz))
            ie = mi.Int32(dr.floor((el + el_half) * inv_del))
            inside = (
                visible & (ir >= 0) & (ir < n_r) & (ia >= 0) & (ia < n_a) & (ie >= 0) & (ie < n_e)
            )
            idx = mi.UInt32((ir * n_a + ia) * n_e + ie)
            pw = a_re * a_re + a_im * a_im
            for target, value in zip(
                acc, (a_re, a_im, pw, pw * rng_m, pw * az, pw * el), strict=True
            ):
                dr.scatter_reduce(dr.ReduceOp.Add, target, value, idx, inside)

            if bounce + 1 < radar.max_bounces:
                carry_re = cg_re * spec
                carry_im = cg_im * spec
                reflected = ray.d + 2.0 * cos_in * normal
                ray = si.spawn_ray(reflected)
                prev_hit = hit
                active = valid & ((carry_re * carry_re + carry_im * carry_im) > 1e-10)
                dr.eval(ray, prev_hit, carry_re, carry_im, path_in, active, *acc, hits)

        dr.eval(*acc, hits)
        dr.sync_thread()
        t2 = time.perf_counter()
        arrays = [a.numpy().astype(np.float64) for a in acc]
        accumulator = Accumulator(*arrays)
        t3 = time.perf_counter()
        return TraceResult(
            accumulator=accumulator,
            n_rays=n,
            hits_per_bounce=tuple(int(h) for h in hits.numpy()),
            seconds={"rays": t1 - t0, "trace": t2 - t1, "readback": t3 - t2},
        )

    # ------------------------------------------------------------------------------------
    def intersect_only(
        self, radar: RadarConfig, pose: np.ndarray | None = None, *, seed: int | None = None
    ) -> dict[str, float]:
        """Bare Mitsuba baseline: the same rays and bounces, intersections + mirror only.

        Used by the benchmark to measure the simulator's overhead over ``ray_intersect``.
        Returns ``{"seconds": ..., "n_intersections": ...}``.
        """
        mi, dr = self._mi, self._dr
        pose = check_pose(pose)
        prep = self._prepare(radar, seed)
        ray, _ = self._primary_rays(prep, pose)
        n = prep.n_rays
        dr.eval(ray)
        dr.sync_thread()
        active = dr.full(mi.Bool, True, n)
        t0 = time.perf_counter()
        count = 0
        for bounce in range(radar.max_bounces):
            si = self._scene.ray_intersect(ray, active)
            valid = active & si.is_valid()
            if bounce + 1 < radar.max_bounces:
                normal = si.n
                ray = si.spawn_ray(ray.d - 2.0 * dr.dot(ray.d, normal) * normal)
                active = valid
                dr.eval(ray, active)
            else:
                dr.eval(si.t, si.p, si.n, si.prim_index, valid)
            count += n
        dr.sync_thread()
        return {"seconds": time.perf_counter() - t0, "n_intersections": count}
