"""Mitsuba 3 / Dr.Jit radar ray tracer: rays over the FOV -> one bounce loop -> cells or paths.

The scene (all meshes merged into one in-memory ``mi.Mesh``, one BVH) is built once per
:class:`RadarScene`; per-face material indices select the Fresnel tables and the roughness
coefficients, per-face object indices let a transmitted ray leave the object it entered.

Everything per ray is one vectorised Dr.Jit program; a Python loop runs over bounces only,
in :meth:`RadarScene._interactions` — the one bounce loop. It yields, per bounce, what each
interaction sends back to the radar (specular and diffuse samples without the carrier phase,
path length, first and last interaction point, visibility), after the return model of
:mod:`sim2radar.radar.returns`. Two consumers read it:

* :meth:`RadarScene.trace` (the binning simulator) scatter-adds the returns, with carrier
  phase, into per-range-bin fine angle grids on the device (:mod:`sim2radar.radar.binning`);
  only that grid comes back to NumPy.
* :meth:`RadarScene.trace_paths` (the reference radar) keeps every (ray, interaction) return
  as a propagation path (:class:`~sim2radar.radar.paths.PathSet`) for signal-level synthesis.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator, Sequence

import numpy as np

from sim2radar.em import get_material
from sim2radar.hardware import to_drjit
from sim2radar.mesh import MaterialMesh
from sim2radar.radar.binning import Accumulator, TraceResult, array_geometry
from sim2radar.radar.config import RadarConfig, load_radar_config
from sim2radar.radar.frame import RadarFrame, simulate_scene_frame
from sim2radar.radar.paths import PATH_KINDS, PathSet
from sim2radar.radar.returns import (
    DIRECTIVE_LUT_SIZE,
    FRESNEL_LUT_SIZE,
    GOLDEN,
    MAX_RETURN_SLABS,
    MIN_COS,
    continuation_uniforms,
    diffuse_phase_seed,
    directive_lut,
    fresnel_lut,
    polarized_luts,
    ray_angles,
    transmission_lut,
    transmit_probability,
)

__all__ = ["RadarScene", "face_object_ids", "merge_meshes", "check_pose"]

#: Object index meaning "no object" (a ray that is not inside a transmitting slab).
NO_OBJECT = 0xFFFFFFFF
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
_SUM_LIMIT = 2**61


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


def _mesh_list(meshes: Sequence[MaterialMesh]) -> list[MaterialMesh]:
    if isinstance(meshes, MaterialMesh):
        return [meshes]
    meshes = list(meshes)
    if not meshes:
        raise ValueError("the scene has no meshes; pass a non-empty list of MaterialMesh")
    for i, mesh in enumerate(meshes):
        if not isinstance(mesh, MaterialMesh):
            raise TypeError(f"meshes[{i}] is {type(mesh).__name__}, expected MaterialMesh")
    return meshes


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
    meshes = _mesh_list(meshes)
    materials: list[str] = []
    verts, faces, mats = [], [], []
    offset = 0
    for i, mesh in enumerate(meshes):
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


def face_object_ids(meshes: Sequence[MaterialMesh]) -> np.ndarray:
    """(F,) uint32 — the index of the mesh each face of :func:`merge_meshes` belongs to (one
    mesh = one object = one slab for transmission)."""
    meshes = _mesh_list(meshes)
    return np.concatenate(
        [np.full(len(m.faces), i, dtype=np.uint32) for i, m in enumerate(meshes)]
    )


@dataclasses.dataclass
class _Prepared:
    """Per-(config, seed) device arrays: ray grid, solid angles, tables, random draws."""

    directions: object  # mi.Vector3f (N,), radar frame
    n_rays: int
    solid_angle: object  # mi.Float (N,)
    diffuse_u: object  # mi.Float (N,) in [0, 1)
    spacing_rad: float
    lut_re: object  # reflection table (n_mat * FRESNEL_LUT_SIZE,)
    lut_im: object
    s_coef: object  # S per material
    spec_coef: object  # sqrt(1 - S^2) per material
    directive: bool
    alpha: object | None  # alpha_R per material
    dir_lut: object | None  # F_alpha table (n_mat * DIRECTIVE_LUT_SIZE,)
    transmits: bool
    t_re: object | None  # transmission table (n_mat * FRESNEL_LUT_SIZE,)
    t_im: object | None
    choice_u: list | None  # per bounce: mi.Float (N,) reflect-or-transmit draws
    polarized: bool = False
    slant: tuple[float, float] = (1.0, 0.0)  # (cos, sin) of the antennas' slant from vertical
    pol_r: tuple | None = None  # (te_re, te_im, tm_re, tm_im) reflection tables
    pol_t: tuple | None = None  # (te_re, te_im, tm_re, tm_im) transmission tables


@dataclasses.dataclass
class _Interaction:
    """One bounce of the whole ray batch (Dr.Jit arrays; points in the world frame).

    ``spec`` / ``diff``: the physical-optics and diffuse samples of :mod:`returns` without the
    carrier phase ``e^{-jkL}`` (return-leg gain included); zero where not ``visible``.
    """

    bounce: int
    valid: object  # Bool: the ray hit a surface
    visible: object  # Bool: its return reaches the radar
    hit: object  # Point3f: the interaction point [m]
    arrival: object  # Point3f: last interaction point on the way back [m]
    departure: object  # Point3f: first interaction point of the ray [m]
    path_m: object  # Float: total round-trip length L [m]
    spec_re: object
    spec_im: object
    diff_re: object
    diff_im: object
    n_interactions: object  # UInt32


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
    >>> paths = scene.trace_paths(radar, pose, seed=0)        # the reference radar's input
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
        meshes = _mesh_list(meshes)  # once: an iterator would be consumed by the first pass
        vertices, faces, face_material, self.materials = merge_meshes(meshes)
        self.n_triangles = int(len(faces))
        self.n_objects = len(meshes)
        mesh = mi.Mesh(
            "radar_scene",
            vertex_count=len(vertices),
            face_count=len(faces),
            has_vertex_normals=False,
            has_vertex_texcoords=False,
        )
        params = mi.traverse(mesh)
        params["vertex_positions"] = to_drjit(mi.Float, vertices.ravel(), np.float32)
        params["faces"] = to_drjit(mi.UInt32, faces.ravel(), np.uint32)
        params.update()
        self._scene = mi.load_dict({"type": "scene", "mesh": mesh})
        self._face_material = to_drjit(mi.UInt32, face_material, np.uint32)
        self._face_object = to_drjit(mi.UInt32, face_object_ids(meshes), np.uint32)
        self._prepared: dict[tuple[str, int | None], _Prepared] = {}
        self._tables: dict[str, dict] = {}
        self.build_seconds = time.perf_counter() - t0

    # ------------------------------------------------------------------------------------
    def _prepare(self, radar: RadarConfig, seed: int | None) -> _Prepared:
        """The device arrays of one (config, seed): the seed's ray grid, speckle phases and
        reflect-or-transmit draws over the config's material tables (built once per config)."""
        h = radar.content_hash()
        key = (h, seed)
        if key in self._prepared:
            return self._prepared[key]
        mi = self._mi
        if h not in self._tables:
            if len(self._tables) > 4:
                self._tables.pop(next(iter(self._tables)))
            self._tables[h] = self._material_tables(radar)
        tables = self._tables[h]
        # ray_grid's rays, their directions and solid angles made on the device
        az, el, d_az, d_el = ray_angles(radar.azimuth_fov_rad, radar.elevation_fov_rad,
                                        math.radians(radar.ray_spacing_deg), seed=seed)
        n = len(az)
        az_d, el_d = to_drjit(mi.Float, az, np.float32), to_drjit(mi.Float, el, np.float32)
        dr = self._dr
        sin_az, cos_az = dr.sincos(az_d)
        sin_el, cos_el = dr.sincos(el_d)
        directions = mi.Vector3f(cos_el * cos_az, cos_el * sin_az, sin_el)
        solid_angle = cos_el * (d_az * d_el)
        dr.eval(directions, solid_angle)
        choice = None
        if tables["transmits"]:
            draws = continuation_uniforms(n, radar.max_bounces, seed)
            choice = [to_drjit(mi.Float, row, np.float32) for row in draws]
        prep = _Prepared(
            directions=directions,
            n_rays=n,
            solid_angle=solid_angle,
            diffuse_u=to_drjit(mi.Float, diffuse_phase_seed(n, seed), np.float32),
            spacing_rad=math.sqrt(d_az * d_el),
            choice_u=choice,
            **tables,
        )
        if len(self._prepared) > 8:
            self._prepared.pop(next(iter(self._prepared)))
        self._prepared[key] = prep
        return prep

    def _material_tables(self, radar: RadarConfig) -> dict:
        """Per-material device tables of a config (Fresnel, roughness, lobes, transmission,
        polarised TE/TM): the :class:`_Prepared` fields that no seed changes."""
        mi = self._mi
        sc = radar.scattering
        thickness = [sc.thickness_m(m) for m in self.materials]
        lut = fresnel_lut(self.materials, radar.center_frequency_hz, thickness_m=thickness)
        lut = lut.astype(np.complex64)
        s = np.array([sc.coefficient(m) for m in self.materials], dtype=np.float32)
        directive = sc.model == "directive"
        alpha = dir_lut = None
        if directive:
            alphas = [sc.lobe(m) for m in self.materials]
            alpha = to_drjit(mi.Float, alphas, np.float32)
            dir_lut = to_drjit(mi.Float, directive_lut(alphas).ravel(), np.float32)
        transmits = any(sc.transmits(m) for m in self.materials)
        t_re = t_im = None
        if transmits:
            tl = transmission_lut(
                self.materials,
                radar.center_frequency_hz,
                [d if sc.transmits(m) else None for m, d in zip(self.materials, thickness,
                                                                  strict=True)],
            ).astype(np.complex64)
            t_re, t_im = to_drjit(mi.Float, tl.real.ravel()), to_drjit(mi.Float, tl.imag.ravel())
        pol_r = pol_t = None
        polarized = radar.hardware.polarization != "unpolarized"
        if polarized:
            refl, trans = polarized_luts(self.materials, radar.center_frequency_hz, thickness,
                                         [sc.transmits(m) for m in self.materials])

            def tables(table: np.ndarray) -> tuple:
                table = table.astype(np.complex64)
                return tuple(to_drjit(mi.Float, part(table[:, :, k]).ravel())
                             for k in (0, 1) for part in (np.real, np.imag))

            pol_r, pol_t = tables(refl), tables(trans)
        slant = math.radians(90.0 if radar.hardware.polarization == "horizontal" else 0.0)
        return {
            "lut_re": to_drjit(mi.Float, lut.real.ravel()),
            "lut_im": to_drjit(mi.Float, lut.imag.ravel()),
            "s_coef": to_drjit(mi.Float, s),
            "spec_coef": to_drjit(mi.Float, np.sqrt(1.0 - s**2), np.float32),
            "directive": directive,
            "alpha": alpha,
            "dir_lut": dir_lut,
            "transmits": transmits,
            "t_re": t_re,
            "t_im": t_im,
            "polarized": polarized,
            "slant": (math.cos(slant), math.sin(slant)),
            "pol_r": pol_r,
            "pol_t": pol_t,
        }

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

    def _table(self, re, im, mat, cos_t, active, size: int):
        """Linear interpolation of per-material complex tables sampled over cos in [0, 1]."""
        mi, dr = self._mi, self._dr
        x = dr.clip(cos_t, 0.0, 1.0) * (size - 1)
        i0 = dr.minimum(mi.UInt32(dr.floor(x)), size - 2)
        frac = x - mi.Float(i0)
        base = mat * size + i0
        out_re = dr.lerp(dr.gather(mi.Float, re, base, active),
                         dr.gather(mi.Float, re, base + 1, active), frac)
        if im is None:
            return out_re
        out_im = dr.lerp(dr.gather(mi.Float, im, base, active),
                         dr.gather(mi.Float, im, base + 1, active), frac)
        return out_re, out_im

    def _intersect(self, ray, active, skip_obj):
        """Closest hit; a ray inside a transmitting slab (``skip_obj``) ignores that object's
        faces once (its back face: the slab is the whole object)."""
        mi, dr = self._mi, self._dr
        si = self._scene.ray_intersect(ray, active)
        if skip_obj is None:
            return si
        obj = dr.gather(mi.UInt32, self._face_object, si.prim_index, active & si.is_valid())
        again = active & si.is_valid() & (obj == skip_obj)
        si2 = self._scene.ray_intersect(si.spawn_ray(ray.d), again)
        return dr.select(again, si2, si)

    def _return_leg(self, si, candidate, radar_pos, prep: _Prepared, fields=None):
        """Gain of the way back from ``si`` to the radar through slab materials.

        Returns ``(tau_re, tau_im, visible, arrival, n_slabs, fields)``: each transmissive
        object on the line multiplies ``tau`` by its ``T`` (both faces of one object count
        once), any other surface (or more than :data:`MAX_RETURN_SLABS` slabs) blocks. With
        ``prep.polarized``, ``fields`` (a list of complex field vectors ``(re, im)``) pass each
        slab through its TE/TM transmission instead and ``tau`` stays 1.
        """
        mi, dr = self._mi, self._dr
        tau_re = dr.full(mi.Float, 1.0, dr.width(candidate))
        tau_im = dr.zeros(mi.Float, dr.width(candidate))
        n_slabs = dr.zeros(mi.UInt32, dr.width(candidate))
        arrival = mi.Point3f(si.p)
        visible = mi.Bool(candidate)
        pending = mi.Bool(candidate)
        ray = si.spawn_ray_to(radar_pos)
        for step in range(MAX_RETURN_SLABS + 1):
            sb = self._scene.ray_intersect(ray, pending)
            blocked = pending & sb.is_valid()
            if step == MAX_RETURN_SLABS:
                visible &= ~blocked
                break
            mat = dr.gather(mi.UInt32, self._face_material, sb.prim_index, blocked)
            obj = dr.gather(mi.UInt32, self._face_object, sb.prim_index, blocked)
            u = dr.normalize(ray.d)
            cos_b = dr.abs(dr.dot(u, sb.n))
            if prep.polarized:
                te = self._table(prep.pol_t[0], prep.pol_t[1], mat, cos_b, blocked,
                                 FRESNEL_LUT_SIZE)
                tm = self._table(prep.pol_t[2], prep.pol_t[3], mat, cos_b, blocked,
                                 FRESNEL_LUT_SIZE)
                through = blocked & ((te[0] * te[0] + te[1] * te[1]
                                      + tm[0] * tm[0] + tm[1] * tm[1]) > 0.0)
                s_b = self._te_basis(u, sb.n)
                fields = [tuple(dr.select(through, new, old) for new, old in zip(
                    self._jones(f, s_b, u, u, te, tm), f, strict=True)) for f in fields]
            else:
                t_re, t_im = self._table(prep.t_re, prep.t_im, mat, cos_b, blocked,
                                         FRESNEL_LUT_SIZE)
                through = blocked & ((t_re * t_re + t_im * t_im) > 0.0)
                new_re = tau_re * t_re - tau_im * t_im
                new_im = tau_re * t_im + tau_im * t_re
                tau_re = dr.select(through, new_re, tau_re)
                tau_im = dr.select(through, new_im, tau_im)
            visible &= ~(blocked & ~through)
            n_slabs += dr.select(through, mi.UInt32(1), mi.UInt32(0))
            # leave the object: skip its other face on the way to the radar
            ray2 = sb.spawn_ray_to(radar_pos)
            sb2 = self._scene.ray_intersect(ray2, through)
            obj2 = dr.gather(mi.UInt32, self._face_object, sb2.prim_index,
                             through & sb2.is_valid())
            same = through & sb2.is_valid() & (obj2 == obj)
            arrival = dr.select(through, dr.select(same, sb2.p, sb.p), arrival)
            ray = dr.select(same, sb2.spawn_ray_to(radar_pos), ray2)
            pending = through
        return tau_re, tau_im, visible, arrival, n_slabs, fields

    # -- polarisation (prep.polarized) ---------------------------------------------------
    def _te_basis(self, k, n):
        """Unit TE vector ``s = k x n / |k x n|`` of a wave along ``k`` meeting a surface of
        normal ``n`` (Sionna RT's Jones basis; any vector normal to ``k`` at normal
        incidence)."""
        mi, dr = self._mi, self._dr
        s = dr.cross(k, n)
        n2 = dr.squared_norm(s)
        alt = dr.cross(k, dr.select(dr.abs(k.z) < 0.9, mi.Vector3f(0.0, 0.0, 1.0),
                                    mi.Vector3f(1.0, 0.0, 0.0)))
        s = dr.select(n2 > 1e-12, s, alt)
        return s * dr.rsqrt(dr.maximum(dr.squared_norm(s), 1e-30))

    def _jones(self, field, s, k_in, k_out, te, tm):
        """A complex field vector ``field = (re, im)`` through one interaction: ``r_te (E.s) s +
        r_tm (E.p_in) p_out`` with ``p = k x s`` for the incoming and outgoing directions
        (reflection: ``k_out`` the reflected or returning direction; transmission through a
        slab: ``k_out = k_in``); ``te``, ``tm`` = (re, im) coefficients (ITU-R P.2040-3
        eq. (31) / (43); Sionna RT's sign convention, ``r_tm = -r_te`` at normal incidence).
        """
        dr = self._dr
        e_re, e_im = field
        p_in, p_out = dr.cross(k_in, s), dr.cross(k_out, s)
        es_re, es_im = dr.dot(e_re, s), dr.dot(e_im, s)
        ep_re, ep_im = dr.dot(e_re, p_in), dr.dot(e_im, p_in)
        a_re = te[0] * es_re - te[1] * es_im
        a_im = te[0] * es_im + te[1] * es_re
        b_re = tm[0] * ep_re - tm[1] * ep_im
        b_im = tm[0] * ep_im + tm[1] * ep_re
        return a_re * s + b_re * p_out, a_im * s + b_im * p_out

    def _apply(self, carry, op):
        """``carry`` through one interaction ``op``: ``("scalar", (re, im), None)`` multiplies a
        complex scalar carry; ``("jones", (s, k_in, k_out, te, tm), scale)`` sends a field
        vector through :meth:`_jones` and multiplies it by the real ``scale`` (if any)."""
        kind, args, scale = op
        if kind == "scalar":
            return (carry[0] * args[0] - carry[1] * args[1],
                    carry[0] * args[1] + carry[1] * args[0])
        out = self._jones(carry, *args)
        return out if scale is None else (out[0] * scale, out[1] * scale)

    def _antenna(self, d, up, prep: _Prepared):
        """The antennas' unit polarisation vector for the direction ``d`` [world] (a wave
        leaving the TX along ``d``, or reaching the RX from ``d``): ``cos(slant) v + sin(slant)
        h`` with ``v`` the radar's up axis ``up`` made normal to ``d`` (theta-hat up to sign,
        Sionna RT's "V") and ``h = up x d`` normalised (phi-hat, "H")."""
        dr = self._dr
        c, s = prep.slant
        v = up - dr.dot(up, d) * d
        e = v * (c * dr.rsqrt(dr.maximum(dr.squared_norm(v), 1e-30)))
        if s != 0.0:
            h = dr.cross(up, d)
            e = e + h * (s * dr.rsqrt(dr.maximum(dr.squared_norm(h), 1e-30)))
        return e

    def _interactions(
        self, radar: RadarConfig, pose: np.ndarray, prep: _Prepared, hits
    ) -> Iterator[_Interaction]:
        """THE bounce loop: yield what every ray's interaction sends back, bounce by bounce.

        State (ray, carry, path, ...) is evaluated at the start of each following bounce, in
        one kernel with whatever the consumer scheduled or scattered in between.
        ``hits`` (UInt32, max_bounces) counts the rays that hit something per bounce.
        """
        mi, dr = self._mi, self._dr
        ray, radar_pos = self._primary_rays(prep, pose)
        n = prep.n_rays
        wavenumber = 2.0 * math.pi / radar.wavelength_m
        inv_lambda = 1.0 / radar.wavelength_m

        # C: product of earlier specular factors. With transmission two copies: ``carry`` is
        # amplitude-unbiased (E[C] exact; it weights the coherent PO samples) and ``carry_d``
        # power-unbiased (E|C|^2 exact; it weights the diffuse samples) -- returns.py, item 3.
        # Polarised (prep.polarized), C is the complex field vector (re, im) of the ray instead,
        # starting as the TX antenna's polarisation along the ray.
        up = None
        if prep.polarized:
            up = mi.Vector3f(*(dr.opaque(mi.Float, float(pose[i, 2])) for i in range(3)))
            e0 = self._antenna(ray.d, up, prep)
            carry = (e0, dr.zeros(mi.Vector3f, n))
        else:
            carry = (dr.full(mi.Float, 1.0, n), dr.zeros(mi.Float, n))
        carry_d = carry
        path_in = dr.zeros(mi.Float, n)
        active = dr.full(mi.Bool, True, n)
        d_omega = prep.solid_angle
        prev_hit = mi.Point3f(radar_pos)
        departure = mi.Point3f(radar_pos)
        skip_obj = dr.full(mi.UInt32, NO_OBJECT, n) if prep.transmits else None

        def cmul(a, b):
            return a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0]

        def power(c):
            return dr.squared_norm(c[0]) + dr.squared_norm(c[1])

        for bounce in range(radar.max_bounces):
            if bounce > 0:
                state = [ray, prev_hit, departure, *carry, path_in, active, hits]
                if prep.transmits:
                    state += [skip_obj, *carry_d]
                dr.eval(*state)
            si = self._intersect(ray, active, skip_obj if bounce > 0 else None)
            valid = active & si.is_valid()
            dr.scatter_reduce(dr.ReduceOp.Add, hits, mi.UInt32(1), mi.UInt32(bounce), valid)
            normal = si.n
            cos_in = -dr.dot(ray.d, normal)
            normal = dr.select(cos_in < 0, -normal, normal)
            cos_in = dr.abs(cos_in)
            hit = si.p
            if bounce == 0:
                departure = mi.Point3f(hit)
            # unfold the path from the true hit points: si.t is measured from the spawned
            # origin, which Mitsuba offsets ~(1+|p|) 1e-4 m off the surface (~0.1 lambda)
            path_in = path_in + dr.select(valid, dr.norm(hit - prev_hit), 0.0)
            to_radar = radar_pos - hit
            r_out = dr.norm(to_radar)
            u_out = to_radar / r_out
            cos_out = dr.dot(u_out, normal)
            visible = valid & (cos_out > 0)
            arrival = mi.Point3f(hit)
            mat = dr.gather(mi.UInt32, self._face_material, si.prim_index, valid)
            s_coef = dr.gather(mi.Float, prep.s_coef, mat, valid)
            spec = dr.gather(mi.Float, prep.spec_coef, mat, valid)
            reflected = ray.d + 2.0 * cos_in * normal
            if prep.polarized:
                # the field sent back toward the radar, TE/TM on this surface (returns.py)
                r_te = self._table(prep.pol_r[0], prep.pol_r[1], mat, cos_in, valid,
                                   FRESNEL_LUT_SIZE)
                r_tm = self._table(prep.pol_r[2], prep.pol_r[3], mat, cos_in, valid,
                                   FRESNEL_LUT_SIZE)
                s_vec = self._te_basis(ray.d, normal)
                fields = [self._jones(carry, s_vec, ray.d, u_out, r_te, r_tm)]
                if prep.transmits:
                    fields.append(self._jones(carry_d, s_vec, ray.d, u_out, r_te, r_tm))
            n_ret = mi.UInt32(0)
            tau = None
            if bounce > 0:
                if prep.transmits:
                    tau_re, tau_im, visible, arrival, n_ret, fields_out = self._return_leg(
                        si, visible, radar_pos, prep, fields if prep.polarized else None)
                    if prep.polarized:
                        fields = fields_out
                    else:
                        tau = (tau_re, tau_im)
                else:
                    visible &= ~self._scene.ray_test(si.spawn_ray_to(radar_pos), visible)

            if prep.polarized:  # received: the RX antenna's polarisation . field
                e_rx = self._antenna(-u_out, up, prep)
                cg = (dr.dot(e_rx, fields[0][0]), dr.dot(e_rx, fields[0][1]))
                cd = (dr.dot(e_rx, fields[-1][0]), dr.dot(e_rx, fields[-1][1])) \
                    if prep.transmits else cg
            else:
                gamma = self._table(prep.lut_re, prep.lut_im, mat, cos_in, valid,
                                    FRESNEL_LUT_SIZE)
                cg = cmul(carry, gamma)                                     # C * Gamma
                if tau is not None:
                    cg = cmul(cg, tau)                                      # C * Gamma * tau
                cd = cg
                if prep.transmits:  # the diffuse sample's C * Gamma * tau
                    cd = cmul(carry_d, gamma)
                    if tau is not None:
                        cd = cmul(cd, tau)
            cg_re, cg_im = cg
            cd_re, cd_im = cd

            # physical-optics (specular) sample with the Nyquist window
            ci = dr.maximum(cos_in, MIN_COS)
            grad = ray.d - u_out
            grad_t = grad - dr.dot(grad, normal) * normal
            dphi = wavenumber * dr.norm(grad_t) * path_in * prep.spacing_rad / ci
            xw = dr.clip((dphi - 0.5 * math.pi) / (0.5 * math.pi), 0.0, 1.0)
            window = dr.select(xw < 1.0, dr.square(dr.cos(0.5 * math.pi * xw)), 0.0)
            amp_c = (
                inv_lambda * spec * d_omega * (cos_in + cos_out) / (2.0 * ci) * (path_in / r_out)
            ) * window
            amp_c = dr.select(visible, amp_c, 0.0)
            # diffuse sample: S sqrt(dOmega f_s) / r_o with a per-ray speckle phase
            if prep.directive:
                alpha = dr.gather(mi.Float, prep.alpha, mat, valid)
                f_norm = self._table(prep.dir_lut, None, mat, cos_in, valid, DIRECTIVE_LUT_SIZE)
                x = dr.maximum(0.5 * (1.0 + dr.dot(u_out, reflected)), 1e-30)
                pattern = dr.exp(alpha * dr.log(x)) / f_norm
            else:
                pattern = dr.maximum(cos_out, 0.0) / math.pi
            amp_d = s_coef * dr.sqrt(d_omega * pattern) / r_out
            amp_d = dr.select(visible, amp_d, 0.0)
            u = prep.diffuse_u + bounce * GOLDEN
            sin_d, cos_d = dr.sincos(-2.0 * math.pi * (u - dr.floor(u)))

            record = _Interaction(
                bounce=bounce,
                valid=valid,
                visible=visible,
                hit=hit,
                arrival=arrival,
                departure=departure,
                path_m=path_in + r_out,
                spec_re=-cg_im * amp_c,  # j * C Gamma * amp_c
                spec_im=cg_re * amp_c,
                diff_re=(cd_re * cos_d - cd_im * sin_d) * amp_d,
                diff_im=(cd_re * sin_d + cd_im * cos_d) * amp_d,
                n_interactions=mi.UInt32(bounce + 1) + n_ret,
            )

            if bounce + 1 < radar.max_bounces:
                # continuation: specular reflection, or (slabs) a seeded reflect-or-transmit
                direction = reflected
                if prep.polarized:
                    r_op = ("jones", (s_vec, ray.d, reflected, r_te, r_tm), spec)
                else:
                    r_op = ("scalar", (gamma[0] * spec, gamma[1] * spec), None)
                if prep.transmits:
                    if prep.polarized:
                        t_te = self._table(prep.pol_t[0], prep.pol_t[1], mat, cos_in, valid,
                                           FRESNEL_LUT_SIZE)
                        t_tm = self._table(prep.pol_t[2], prep.pol_t[3], mat, cos_in, valid,
                                           FRESNEL_LUT_SIZE)
                        t_op = ("jones", (s_vec, ray.d, ray.d, t_te, t_tm), None)
                        e2 = dr.maximum(power(carry), 1e-30)
                        q = transmit_probability(power(self._apply(carry, r_op)) / e2,
                                                 power(self._apply(carry, t_op)) / e2)
                    else:
                        t_c = self._table(prep.t_re, prep.t_im, mat, cos_in, valid,
                                          FRESNEL_LUT_SIZE)
                        t_op = ("scalar", t_c, None)
                        q = transmit_probability(
                            (gamma[0] * gamma[0] + gamma[1] * gamma[1]) * spec * spec,
                            t_c[0] * t_c[0] + t_c[1] * t_c[1])
                    reflect = prep.choice_u[bounce] >= q
                    w = dr.select(reflect, 1.0 - q, q)  # probability of the chosen branch
                    k_c = dr.rcp(dr.maximum(w, 1e-30))  # amplitude-unbiased weight
                    k_d = dr.rsqrt(dr.maximum(w, 1e-30))  # power-unbiased weight
                    carry = tuple(dr.select(reflect, a, b) * k_c for a, b in zip(
                        self._apply(carry, r_op), self._apply(carry, t_op), strict=True))
                    carry_d = tuple(dr.select(reflect, a, b) * k_d for a, b in zip(
                        self._apply(carry_d, r_op), self._apply(carry_d, t_op), strict=True))
                    direction = dr.select(reflect, reflected, ray.d)
                    obj = dr.gather(mi.UInt32, self._face_object, si.prim_index, valid)
                    skip_obj = dr.select(reflect, mi.UInt32(NO_OBJECT), obj)
                else:
                    carry = self._apply(carry, r_op)
                    carry_d = carry
                ray = si.spawn_ray(direction)
                prev_hit = hit
                strength = power(carry)
                if prep.transmits:
                    strength = dr.maximum(strength, power(carry_d))
                active = valid & (strength > 1e-10)
            yield record

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

    def trace(
        self, radar: RadarConfig, pose: np.ndarray | None = None, *, seed: int | None = None
    ) -> TraceResult:
        """Trace one frame and return the accumulated (not yet beamformed) returns.

        Each visible return, with its carrier phase ``e^{-jkL}``, is added to its range bin
        and fine azimuth point once per element row (:mod:`sim2radar.radar.binning`).
        """
        mi, dr = self._mi, self._dr
        pose = check_pose(pose)
        t0 = time.perf_counter()
        prep = self._prepare(radar, seed)
        geom = array_geometry(radar)
        t1 = time.perf_counter()

        inv_lambda = 1.0 / radar.wavelength_m
        n_r, n_a, n_e = radar.n_range_bins, radar.n_azimuth_bins, radar.n_elevation_bins
        n_z, m_fine = len(geom.z_half_wl), geom.fine_az
        inv_dr = 1.0 / radar.range_resolution_m
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

        for it in self._interactions(radar, pose, prep, hits):
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
            rng_m = 0.5 * it.path_m
            ir = mi.Int32(dr.floor(rng_m * inv_dr + 0.5))
            keep = it.visible & (ir >= 0) & (ir < n_r)
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
        sums = cells.numpy().reshape(-1, 2)
        accumulator = Accumulator(
            grid=np.ascontiguousarray(grid.numpy()).view(np.complex64).reshape(n_z, n_r, m_fine),
            power=sums[:, 0].copy(),
            range_w=sums[:, 1].copy(),
        )
        t3 = time.perf_counter()
        return TraceResult(
            accumulator=accumulator,
            n_rays=prep.n_rays,
            hits_per_bounce=tuple(int(h) for h in hits.numpy()),
            seconds={"rays": t1 - t0, "trace": t2 - t1, "readback": t3 - t2},
        )

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

        mi, dr = self._mi, self._dr
        pose = check_pose(pose)
        t0 = time.perf_counter()
        prep = self._prepare(radar, seed)
        t1 = time.perf_counter()
        hits = dr.zeros(mi.UInt32, radar.max_bounces)
        records = []
        for it in self._interactions(radar, pose, prep, hits):
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
        mi, dr = self._mi, self._dr
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
        pi = self._scene.ray_intersect_preliminary(ray)
        t = dr.select(pi.is_valid(), pi.t, dr.inf)
        return np.asarray(t.numpy(), dtype=np.float64)

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
