"""Mitsuba 3 / Dr.Jit radar ray tracer: rays over the FOV -> one bounce loop -> cells or paths.

The scene (all meshes merged into one in-memory ``mi.Mesh``, one BVH) is built once per
:class:`RadarScene`; per-face material indices select the Fresnel tables and the roughness
coefficients, per-face object indices let a transmitted ray leave the object it entered.

Everything per ray is one vectorised Dr.Jit program; a Python loop runs over bounces only,
in :func:`~sim2radar.radar.raytrace_bounces.interactions` — the one bounce loop. It yields, per bounce, what each
interaction sends back to the radar (specular and diffuse samples without the carrier phase,
path length, first and last interaction point, visibility), after the return model of
:mod:`sim2radar.radar.returns`. Two consumers read it:

* :meth:`RadarScene.trace` (the binning simulator) scatter-adds the returns, with carrier
  phase, into per-range-bin fine angle grids on the device (:mod:`sim2radar.radar.binning`);
  only that grid comes back to NumPy.
* :meth:`RadarScene.trace_paths` (the reference radar) keeps every (ray, interaction) return
  as a propagation path (:class:`~sim2radar.radar.paths.PathSet`) for signal-level synthesis.

Where each part is:

- this module — :class:`RadarScene`: it holds the built scene (a
  :class:`~sim2radar.radar.raytrace_bounces.SceneHandle`) and the per-(config, seed) cache, and
  has the two consumers above, the visibility query :meth:`RadarScene.first_hit_distance` and the
  bare-Mitsuba baseline :meth:`RadarScene.intersect_only`;
- :mod:`sim2radar.radar.raytrace_mesh` — meshes merged into one with per-face material and
  object indices, the pose check (NumPy; re-exported here);
- :mod:`sim2radar.radar.raytrace_tables` — the device tables and ray grid of a config and seed;
- :mod:`sim2radar.radar.raytrace_bounces` — the scene handle (Mitsuba scene, per-face material
  and object indices) and the bounce loop, functions over the handle;
- :mod:`sim2radar.radar.raytrace_polarization` — the Jones-vector operations of polarised rays.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from sim2radar.hardware import ReleasedUnderLock, drjit_serial, to_drjit
from sim2radar.mesh import MaterialMesh
from sim2radar.radar.binning import Accumulator, TraceResult, array_geometry
from sim2radar.radar.config import RadarConfig, load_radar_config
from sim2radar.radar.detection_torch import DeviceAccumulator
from sim2radar.radar.frame import DeviceTrace, RadarFrame, simulate_scene_frame
from sim2radar.radar.link_budget import pattern_exponent
from sim2radar.radar.paths import PATH_KINDS, PathSet
from sim2radar.radar.raytrace_bounces import SceneHandle, build_scene, interactions, primary_rays
from sim2radar.radar.raytrace_mesh import check_pose, face_object_ids, merge_meshes
from sim2radar.radar.raytrace_tables import Prepared, material_tables, prepare_rays

__all__ = ["RadarScene", "face_object_ids", "merge_meshes", "check_pose"]

#: Default margin below the receiver noise per cell under which single paths are pruned [dB].
PRUNE_BELOW_NOISE_DB = 40.0
#: Fixed-point steps of :meth:`RadarScene.trace`'s sums. Returns are added up as 64-bit integers
#: (``round(value / step)``): integer addition does not depend on the order in which the
#: threads' atomic adds land, so one pose and seed give the same bits on every run (float
#: atomics did not: 18 of 24 frames of two identical runs differed by up to 8e-6 m).
#: Amplitude step 2^-40 ~ 9.1e-13 [sim. amplitude]: 122 dB under the ``ti-mmwcas`` receiver
#: noise (sqrt N0 ~ 1.2e-6); sums up to 2^23 ~ 8.4e6 (a metal wall 5 cm in front of the radar
#: gives 0.45). Float32 returns above 2^-16 convert exactly.
AMPLITUDE_STEP = 2.0**-40
#: Power and power x range step 2^-54 ~ 5.6e-17 [sim. |a|^2, |a|^2 m]: 44 dB under N0 (~1.4e-12);
#: sums up to 2^9 = 512 (the metal wall at 5 cm gives 0.032; power grows as 1/r^2, so only a
#: radar within ~0.5 mm of a metal surface could overflow).
POWER_STEP = 2.0**-54
#: A margin under the 2^63 steps a 64-bit sum holds; the tests check the headroom against it.
SUM_LIMIT = 2**61


def _element_gain(dr, x, y, z, q_az: float, q_el: float):
    """One-way element power gain ``cos^q_az(az) cos^q_el(el)`` of radar-frame direction
    ``(x, y, z)`` (Dr.Jit twin of :func:`sim2radar.radar.link_budget.element_power_pattern`:
    0 behind the array)."""
    h2 = x * x + y * y
    cos_az = dr.select(x > 0, x * dr.rsqrt(dr.maximum(h2, 1e-24)), 0.0)
    cos_el = dr.sqrt(h2) * dr.rsqrt(dr.maximum(h2 + z * z, 1e-24))
    return dr.power(cos_az, q_az) * dr.power(cos_el, q_el)


class RadarScene(ReleasedUnderLock):
    """A scene built once for Mitsuba, simulated from many radar poses.

    Parameters
    ----------
    meshes : sequence of MaterialMesh
        Scene geometry in the world frame [m]; each mesh's material must be known to
        :mod:`sim2radar.em`.

    Attributes
    ----------
    handle : SceneHandle — the built scene the bounce loop traces
        (:func:`sim2radar.radar.raytrace_bounces.build_scene`).
    variant : str — the Mitsuba variant that traces it.
    n_triangles, n_objects : int — faces and meshes merged.
    build_seconds : float — wall time of the build [s].

    Examples
    --------
    >>> scene = RadarScene(meshes)
    >>> frames = [scene.simulate(radar, pose) for pose in poses]
    >>> paths = scene.trace_paths(radar, pose, seed=0)        # the reference radar's input
    """

    @drjit_serial
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

        self.handle: SceneHandle = build_scene(mi, dr, meshes)
        self.n_triangles = self.handle.n_triangles
        self.n_objects = self.handle.n_objects
        self._prepared: dict[tuple[str, int | None], Prepared] = {}
        self._tables: dict[str, dict] = {}
        self.build_seconds = time.perf_counter() - t0

    @property
    def materials(self) -> list[str]:
        """Normalised material names of the scene (index = per-face material index)."""
        return list(self.handle.materials)

    # ------------------------------------------------------------------------------------
    def _prepare(self, radar: RadarConfig, seed: int | None) -> Prepared:
        """The device arrays of one (config, seed): the seed's ray grid, speckle phases and
        reflect-or-transmit draws over the config's material tables (built once per config)."""
        h = radar.content_hash()
        key = (h, seed)
        if key in self._prepared:
            return self._prepared[key]
        if h not in self._tables:
            if len(self._tables) > 4:
                self._tables.pop(next(iter(self._tables)))
            self._tables[h] = material_tables(self.handle.mi, self.materials, radar)
        prep = prepare_rays(self.handle.mi, self.handle.dr, radar, seed, self._tables[h])
        if len(self._prepared) > 8:
            self._prepared.pop(next(iter(self._prepared)))
        self._prepared[key] = prep
        return prep

    # ------------------------------------------------------------------------------------
    def simulate(
        self,
        radar: RadarConfig | str,
        pose: np.ndarray | None = None,
        *,
        return_cube: bool = False,
        seed: int | None = None,
        velocity_mps: np.ndarray | None = None,
    ) -> RadarFrame:
        """Simulate one frame from ``pose``; see :func:`sim2radar.radar.simulate_frame`."""
        radar = radar if isinstance(radar, RadarConfig) else load_radar_config(radar)
        return simulate_scene_frame(self, radar, pose, return_cube=return_cube, seed=seed,
                                    velocity_mps=velocity_mps)

    @drjit_serial
    def trace(
        self, radar: RadarConfig, pose: np.ndarray | None = None, *, seed: int | None = None
    ) -> TraceResult:
        """Trace one frame and return the accumulated (not yet beamformed) returns.

        Each visible return, with its carrier phase ``e^{-jkL}``, the antenna elements'
        two-way gain toward its first and from its last interaction (``hardware``'s
        ``cos^q`` patterns, as the signal-level synthesis applies them) and the receiver's IF
        response (:mod:`sim2radar.radar.receiver`: the anti-alias roll-off near ``R_max``; a
        path beyond it aliases into bin ``i mod N``), is added to its range bin and fine
        azimuth point once per element row (:mod:`sim2radar.radar.binning`).
        """
        grid, cells, hits, n_rays, seconds = self._trace_sums(radar, pose, seed)
        t2 = time.perf_counter()
        geom = array_geometry(radar)
        n_z, n_r, m_fine = len(geom.z_half_wl), radar.n_range_bins, geom.fine_az
        sums = cells.numpy().reshape(-1, 2)
        accumulator = Accumulator(
            grid=np.ascontiguousarray(grid.numpy()).view(np.complex64).reshape(n_z, n_r, m_fine),
            power=sums[:, 0].copy(),
            range_w=sums[:, 1].copy(),
        )
        seconds["readback"] = time.perf_counter() - t2
        return TraceResult(
            accumulator=accumulator,
            n_rays=n_rays,
            hits_per_bounce=tuple(int(h) for h in hits.numpy()),
            seconds=seconds,
        )

    @drjit_serial
    def trace_on_device(
        self, radar: RadarConfig, pose: np.ndarray | None = None, *, seed: int | None = None
    ) -> DeviceTrace:
        """:meth:`trace` with the sums left on the device Mitsuba traces on: torch tensors
        shared with Dr.Jit through DLPack (CUDA tensors on ``cuda_ad_rgb``, CPU tensors on
        ``llvm_ad_rgb``); only the per-bounce hit counts are read back. The frame's detection
        then runs there (:mod:`sim2radar.radar.detection_torch`)."""
        grid, cells, hits, n_rays, seconds = self._trace_sums(radar, pose, seed)
        t2 = time.perf_counter()
        geom = array_geometry(radar)
        n_z, n_r, m_fine = len(geom.z_half_wl), radar.n_range_bins, geom.fine_az
        import torch

        sums = cells.torch().reshape(-1, 2)
        accumulator = DeviceAccumulator(
            grid=torch.view_as_complex(grid.torch().reshape(n_z, n_r, m_fine, 2)),
            power=sums[:, 0],
            range_w=sums[:, 1],
        )
        hits_per_bounce = tuple(int(h) for h in hits.numpy())
        seconds["readback"] = time.perf_counter() - t2
        return DeviceTrace(accumulator=accumulator, n_rays=n_rays,
                           hits_per_bounce=hits_per_bounce, seconds=seconds)

    def _trace_sums(self, radar: RadarConfig, pose: np.ndarray | None, seed: int | None):
        """The bounce loop's returns summed on the device (:meth:`trace`): ``(grid, cells,
        hits, n_rays, seconds)`` with ``grid`` interleaved (re, im) float32 of the
        (n_z, n_range, M) fine grid, ``cells`` interleaved (power, power x range) float64 per
        cell, both evaluated (Dr.Jit arrays)."""
        mi, dr = self.handle.mi, self.handle.dr
        pose = check_pose(pose)
        t0 = time.perf_counter()
        prep = self._prepare(radar, seed)
        geom = array_geometry(radar)
        t1 = time.perf_counter()

        inv_lambda = 1.0 / radar.wavelength_m
        n_r, n_a, n_e = radar.n_range_bins, radar.n_azimuth_bins, radar.n_elevation_bins
        n_z, m_fine = len(geom.z_half_wl), geom.fine_az
        inv_dr = 1.0 / radar.range_resolution_m
        n_if = dr.width(prep.if_re)
        alias_m = n_r * radar.range_resolution_m
        q_az = pattern_exponent(radar.hardware.azimuth_hpbw_deg)
        q_el = pattern_exponent(radar.hardware.elevation_hpbw_deg)
        inv_ua, inv_ue = 1.0 / radar.azimuth_bin_u, 1.0 / radar.elevation_bin_u
        radar_pos = [dr.opaque(mi.Float, float(v)) for v in pose[:3, 3]]
        # world -> radar rotation (R^T) as opaque scalars so a new pose reuses the kernel
        rt = [[dr.opaque(mi.Float, float(pose[j, i])) for j in range(3)] for i in range(3)]

        # interleaved (re, im) and (power, power * range) pairs: packet scatters of 2 values are
        # ~3x faster than two scalar ones. The sums are 64-bit fixed point (AMPLITUDE_STEP,
        # POWER_STEP): the same bits whatever order the threads' atomic adds land in.
        int64, pair64 = dr.int64_array_t(mi.Float), dr.int64_array_t(mi.Array2f)
        to_amp, to_pow = 1.0 / AMPLITUDE_STEP, 1.0 / POWER_STEP
        grid = dr.zeros(int64, 2 * n_z * n_r * m_fine)
        cells = dr.zeros(int64, 2 * n_r * n_a * n_e)
        hits = dr.zeros(mi.UInt32, radar.max_bounces)

        for it in interactions(self.handle, radar, pose, prep, hits):
            a0_re = it.spec_re + it.diff_re
            a0_im = it.spec_im + it.diff_im
            # e^{-jkL}: reduce to the fractional number of wavelengths first (float32 sincos
            # loses accuracy for |arguments| of 1e4 rad, i.e. paths of a few metres)
            cycles = it.path_m * inv_lambda
            sin_p, cos_p = dr.sincos(-2.0 * math.pi * (cycles - dr.floor(cycles)))
            a_re = a0_re * cos_p - a0_im * sin_p
            a_im = a0_re * sin_p + a0_im * cos_p
            # arrival direction cosines in the radar frame
            q = it.arrival - mi.Point3f(*radar_pos)
            qx = rt[0][0] * q.x + rt[0][1] * q.y + rt[0][2] * q.z
            qy = rt[1][0] * q.x + rt[1][1] * q.y + rt[1][2] * q.z
            qz = rt[2][0] * q.x + rt[2][1] * q.y + rt[2][2] * q.z
            inv_q = dr.rsqrt(dr.maximum(qx * qx + qy * qy + qz * qz, 1e-24))
            ua, ue = qy * inv_q, qz * inv_q
            # the antenna elements' two-way gain: TX toward the first interaction, RX from the
            # last (link_budget.two_way_pattern_gain, the signal-level synthesis' too)
            d = it.departure - mi.Point3f(*radar_pos)
            gain = dr.sqrt(_element_gain(dr, qx, qy, qz, q_az, q_el) * _element_gain(
                dr, *(sum(rt[i][j] * c for j, c in enumerate((d.x, d.y, d.z)))
                      for i in range(3)), q_az, q_el))
            a_re, a_im = a_re * gain, a_im * gain
            rng_m = 0.5 * it.path_m
            # the receiver's IF chain (sim2radar.radar.receiver): the response of the return's
            # true range bin; complex sampling shows it in that bin modulo n_r (a path beyond
            # R_max aliases, attenuated by the anti-alias roll-off)
            ir_true = mi.Int32(dr.floor(rng_m * inv_dr + 0.5))
            g_if = mi.UInt32(dr.clip(ir_true, 0, n_if - 1))
            h_re = dr.gather(mi.Float, prep.if_re, g_if)
            h_im = dr.gather(mi.Float, prep.if_im, g_if)
            a_re, a_im = a_re * h_re - a_im * h_im, a_re * h_im + a_im * h_re
            wraps = ir_true // n_r
            ir = ir_true - wraps * n_r
            rng_m = rng_m - mi.Float(wraps) * alias_m  # apparent range, for the range sums
            keep = it.visible & (ir_true >= 0)
            g = mi.Int32(dr.floor((ua + 1.0) * (0.5 * m_fine) + 0.5))
            g = dr.select(g >= m_fine, g - m_fine, g)
            ug_phase = -math.pi * geom.x_shift * (-1.0 + (2.0 / m_fine) * mi.Float(g))
            for j, z in enumerate(geom.z_half_wl):
                sin_z, cos_z = dr.sincos(math.pi * float(z) * ue + ug_phase)
                v_re = a_re * cos_z - a_im * sin_z
                v_im = a_re * sin_z + a_im * cos_z
                idx = mi.UInt32((j * n_r + ir) * m_fine + g)
                v = pair64(int64(dr.round(v_re * to_amp)), int64(dr.round(v_im * to_amp)))
                dr.scatter_reduce(dr.ReduceOp.Add, grid, v, idx, keep)
            ia = mi.Int32(dr.floor(ua * inv_ua + 0.5)) + n_a // 2
            ie = mi.Int32(dr.floor(ue * inv_ue + 0.5)) + n_e // 2
            cell_ok = keep & (ia >= 0) & (ia < n_a) & (ie >= 0) & (ie < n_e)
            cell = mi.UInt32((ir * n_a + ia) * n_e + ie)
            pw = (a_re * a_re + a_im * a_im) * to_pow
            p = pair64(int64(dr.round(pw)), int64(dr.round(pw * rng_m)))
            dr.scatter_reduce(dr.ReduceOp.Add, cells, p, cell, cell_ok)

        # back to float on the device (float32 grid, as the float sums were; float64 cells)
        grid = mi.Float(grid) * AMPLITUDE_STEP
        cells = dr.float64_array_t(mi.Float)(cells) * POWER_STEP
        dr.eval(grid, cells, hits)
        dr.sync_thread()
        t2 = time.perf_counter()
        return grid, cells, hits, prep.n_rays, {"rays": t1 - t0, "trace": t2 - t1}

    @drjit_serial
    def trace_paths(
        self,
        radar: RadarConfig,
        pose: np.ndarray | None = None,
        *,
        seed: int | None = None,
        velocity_mps: np.ndarray | None = None,
        prune_below_noise_db: float | None = PRUNE_BELOW_NOISE_DB,
        merge_voxel_m: float | None = None,
    ) -> PathSet:
        """Trace one frame and return its propagation paths (the reference radar's input).

        One path per ray and interaction whose return reaches the radar, from the same bounce
        loop as :meth:`trace`: amplitude without the carrier phase (specular + diffuse sample
        of :mod:`sim2radar.radar.returns`), total length, first/last interaction point in the
        radar frame.

        Parameters
        ----------
        radar : RadarConfig — ``max_bounces`` interactions per ray (reflections and, with
            ``scattering.transmission``, slab transmissions); ``scattering.model`` picks the
            diffuse pattern.
        pose : (4, 4), optional — radar-to-world transform (None: identity).
        seed : int, optional — ray jitter, speckle phases and reflect-or-transmit draws
            (None: the regular grid and fixed streams).
        velocity_mps : (3,), optional — radar velocity in the radar frame [m/s] for a static
            scene: ``range_rate = (dL/dt) / 2 = -v . (u_dep + u_arr) / 2`` with ``u`` the unit
            vectors from the radar to the first / last interaction point. None: 0.
        prune_below_noise_db : float or None — drop paths whose power ``|a|^2`` is this far
            below the receiver noise per cell (:func:`sim2radar.radar.link_budget.
            noise_power_per_cell`); None keeps all. At 40 dB even a hundred pruned paths in
            one cell add up to 20 dB below the noise. The pruned count and power are in
            ``stats``.
        merge_voxel_m : float or None — merge paths sharing departure and arrival voxels
            (:meth:`PathSet.merged`); None: no merging.

        Returns
        -------
        PathSet — ``stats``: ``n_rays``, ``hits_per_bounce``, ``n_paths_traced``,
        ``n_pruned``, ``pruned_power``, ``kept_power``, ``noise_power_per_cell``,
        ``n_paths``, ``seconds`` (``rays``, ``trace``, ``readback``, ``merge``).
        """
        from sim2radar.radar.link_budget import noise_power_per_cell

        mi, dr = self.handle.mi, self.handle.dr
        pose = check_pose(pose)
        t0 = time.perf_counter()
        prep = self._prepare(radar, seed)
        t1 = time.perf_counter()
        hits = dr.zeros(mi.UInt32, radar.max_bounces)
        records = []
        for it in interactions(self.handle, radar, pose, prep, hits):
            fields = [it.visible, it.spec_re, it.spec_im, it.diff_re, it.diff_im, it.path_m,
                      it.departure, it.arrival, it.n_interactions]
            dr.schedule(*fields)
            records.append(fields)
        dr.eval(hits)
        dr.sync_thread()
        t2 = time.perf_counter()

        rot, origin = pose[:3, :3], pose[:3, 3]
        parts: dict[str, list[np.ndarray]] = {k: [] for k in
                                              ("spec", "diff", "path", "dep", "arr", "n")}
        n = prep.n_rays

        def host(x) -> np.ndarray:  # (n,) float64 (literals broadcast)
            return np.broadcast_to(np.asarray(x.numpy(), dtype=np.float64), (n,))

        for vis, s_re, s_im, d_re, d_im, path, dep, arr, n_int in records:
            keep = np.broadcast_to(np.asarray(vis.numpy(), dtype=bool), (n,))
            parts["spec"].append(host(s_re)[keep] + 1j * host(s_im)[keep])
            parts["diff"].append(host(d_re)[keep] + 1j * host(d_im)[keep])
            parts["path"].append(host(path)[keep])
            for key, p in (("dep", dep), ("arr", arr)):
                world = np.stack([host(p.x), host(p.y), host(p.z)], 1)[keep]
                parts[key].append((world - origin) @ rot)
            parts["n"].append(host(n_int)[keep].astype(np.int8))
        cat = {k: np.concatenate(v) for k, v in parts.items()}
        amp = cat["spec"] + cat["diff"]
        has_s, has_d = np.abs(cat["spec"]) > 0, np.abs(cat["diff"]) > 0
        kind = np.where(has_s & has_d, PATH_KINDS["mixed"],
                        np.where(has_s, PATH_KINDS["specular"], PATH_KINDS["diffuse"]))
        power = np.abs(amp) ** 2
        nonzero = power > 0
        n0 = noise_power_per_cell(radar)
        keep = nonzero.copy()
        if prune_below_noise_db is not None:
            keep &= power >= n0 * 10.0 ** (-float(prune_below_noise_db) / 10.0)
        dep, arr = cat["dep"][keep], cat["arr"][keep]
        if velocity_mps is None:
            range_rate = np.zeros(int(keep.sum()))
        else:
            v = np.asarray(velocity_mps, dtype=np.float64).reshape(3)
            u_dep = dep / np.maximum(np.linalg.norm(dep, axis=1, keepdims=True), 1e-12)
            u_arr = arr / np.maximum(np.linalg.norm(arr, axis=1, keepdims=True), 1e-12)
            range_rate = -0.5 * (u_dep + u_arr) @ v  # (dL/dt) / 2, dL/dt = -v.(u_dep + u_arr)
        t3 = time.perf_counter()
        stats = {
            "n_rays": prep.n_rays,
            "hits_per_bounce": [int(h) for h in hits.numpy()],
            "n_paths_traced": int(nonzero.sum()),
            "n_pruned": int((nonzero & ~keep).sum()),
            "pruned_power": float(power[nonzero & ~keep].sum()),
            "kept_power": float(power[keep].sum()),
            "noise_power_per_cell": float(n0),
            "seconds": {"rays": t1 - t0, "trace": t2 - t1, "readback": t3 - t2},
        }
        paths = PathSet(
            amplitude=amp[keep].astype(np.complex128),
            path_length_m=cat["path"][keep],
            departure_point_m=dep,
            arrival_point_m=arr,
            range_rate_mps=range_rate,
            n_interactions=cat["n"][keep],
            kind=kind[keep].astype(np.int8),
            stats=stats,
        )
        if merge_voxel_m is not None:
            t4 = time.perf_counter()
            paths = paths.merged(merge_voxel_m, radar.wavelength_m)
            paths.stats["seconds"]["merge"] = time.perf_counter() - t4
        paths.stats["n_paths"] = len(paths)
        return paths

    # ------------------------------------------------------------------------------------
    @drjit_serial
    def first_hit_distance(self, origins_m: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Distance along each ray to the first surface (a visibility query).

        Parameters
        ----------
        origins_m : (N, 3) float — ray origins, world frame [m].
        directions : (N, 3) float — ray directions, world frame (normalised here; non-zero).

        Returns
        -------
        (N,) float64 — distance to the first hit [m], ``inf`` where the ray misses.
        """
        mi, dr = self.handle.mi, self.handle.dr
        o = np.asarray(origins_m, dtype=np.float64)
        d = np.asarray(directions, dtype=np.float64)
        if o.ndim != 2 or o.shape[1] != 3 or d.shape != o.shape:
            raise ValueError(f"origins_m and directions must both be (N, 3), got {o.shape} "
                             f"and {d.shape}")
        if len(o) == 0:
            return np.zeros(0)
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        if not (np.isfinite(o).all() and np.isfinite(d).all()) or np.any(norm <= 0):
            raise ValueError("origins and directions must be finite, directions non-zero")
        ray = mi.Ray3f(to_drjit(mi.Point3f, o.T, np.float32),
                       to_drjit(mi.Vector3f, (d / norm).T, np.float32))
        pi = self.handle.scene.ray_intersect_preliminary(ray)
        t = dr.select(pi.is_valid(), pi.t, dr.inf)
        return np.asarray(t.numpy(), dtype=np.float64)

    @drjit_serial
    def intersect_only(
        self, radar: RadarConfig, pose: np.ndarray | None = None, *, seed: int | None = None
    ) -> dict[str, float]:
        """Bare Mitsuba baseline: the same rays and bounces, intersections + mirror only.

        Used by the benchmark to measure the simulator's overhead over ``ray_intersect``.
        Returns ``{"seconds": ..., "n_intersections": ...}``.
        """
        mi, dr = self.handle.mi, self.handle.dr
        pose = check_pose(pose)
        prep = self._prepare(radar, seed)
        ray, _ = primary_rays(self.handle, prep, pose)
        n = prep.n_rays
        dr.eval(ray)
        dr.sync_thread()
        active = dr.full(mi.Bool, True, n)
        t0 = time.perf_counter()
        count = 0
        for bounce in range(radar.max_bounces):
            si = self.handle.scene.ray_intersect(ray, active)
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
