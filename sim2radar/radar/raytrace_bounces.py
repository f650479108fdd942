"""The bounce loop of the radar ray tracer: what every ray's interactions send back.

A data object and functions over it (as trimesh keeps a mesh and its functions): a
:class:`SceneHandle` is the built scene (the Mitsuba scene of all meshes merged into one, the
per-face material and object indices, :func:`build_scene`), and :func:`interactions` traces the
whole ray batch of a :class:`~sim2radar.radar.raytrace_tables.Prepared` from a pose over it,
bounce by bounce, in one vectorised Dr.Jit program (a Python loop runs over bounces only). It
yields per bounce an :class:`Interaction`: the specular and diffuse samples each interaction
sends back to the radar (without the carrier phase), the path length, the first and last
interaction point and whether the return reaches the radar, after the return model of
:mod:`sim2radar.radar.returns`. Slab transmission picks reflect-or-transmit per ray with seeded
draws and follows the way back through slabs (:func:`return_leg`); with polarised antennas each
ray carries a field vector (:mod:`sim2radar.radar.raytrace_polarization`). The consumers (binned
cells, propagation paths) are :class:`~sim2radar.radar.raytrace.RadarScene`'s methods, which
hold a handle.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from sim2radar.hardware import to_drjit
from sim2radar.mesh import MaterialMesh
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.raytrace_mesh import face_object_ids, merge_meshes, mesh_list
from sim2radar.radar.raytrace_polarization import (
    antenna_polarization,
    apply_interaction,
    jones,
    te_basis,
)
from sim2radar.radar.raytrace_tables import Prepared
from sim2radar.radar.returns import (
    DIRECTIVE_LUT_SIZE,
    FRESNEL_LUT_SIZE,
    GOLDEN,
    MAX_RETURN_SLABS,
    MIN_COS,
    transmit_probability,
)

__all__ = [
    "NO_OBJECT",
    "Interaction",
    "SceneHandle",
    "build_scene",
    "interactions",
    "intersect",
    "lut_lookup",
    "primary_rays",
    "return_leg",
]

#: Object index meaning "no object" (a ray that is not inside a transmitting slab).
NO_OBJECT = 0xFFFFFFFF


@dataclasses.dataclass
class Interaction:
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


@dataclasses.dataclass(frozen=True, eq=False)
class SceneHandle:
    """A scene built for the bounce loop (what :func:`build_scene` makes; read-only).

    Attributes
    ----------
    mi, dr : module — ``mitsuba`` and ``drjit`` with the tracer's variant set.
    scene : mi.Scene — all meshes merged into one ``mi.Mesh`` (one BVH), world frame [m].
    face_material : mi.UInt32 (F,) — per face, the index into ``materials``.
    face_object : mi.UInt32 (F,) — per face, the index of the mesh it came from (one mesh = one
        object = one slab for transmission).
    materials : tuple of str — normalised material names
        (:func:`~sim2radar.radar.raytrace_mesh.merge_meshes`).
    n_triangles : int — faces F.
    n_objects : int — meshes merged.
    """

    mi: Any
    dr: Any
    scene: Any
    face_material: Any
    face_object: Any
    materials: tuple[str, ...]
    n_triangles: int
    n_objects: int


def build_scene(mi, dr, meshes: Sequence[MaterialMesh]) -> SceneHandle:
    """Merge ``meshes`` (world frame [m]) into one Mitsuba mesh and scene, with the per-face
    material and object indices on the device.

    ``mi`` and ``dr`` are the ``mitsuba`` and ``drjit`` modules with a vectorised variant set
    (:func:`sim2radar.hardware.mitsuba_variant`).
    """
    meshes = mesh_list(meshes)  # once: an iterator would be consumed by the first pass
    vertices, faces, face_material, materials = merge_meshes(meshes)
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
    return SceneHandle(
        mi=mi,
        dr=dr,
        scene=mi.load_dict({"type": "scene", "mesh": mesh}),
        face_material=to_drjit(mi.UInt32, face_material, np.uint32),
        face_object=to_drjit(mi.UInt32, face_object_ids(meshes), np.uint32),
        materials=tuple(materials),
        n_triangles=int(len(faces)),
        n_objects=len(meshes),
    )


def primary_rays(handle: SceneHandle, prep: Prepared, pose: np.ndarray):
    """Rotate the cached radar-frame grid by the pose (opaque scalars: no recompilation)."""
    mi, dr = handle.mi, handle.dr
    rot = [[dr.opaque(mi.Float, float(pose[i, j])) for j in range(3)] for i in range(3)]
    origin = mi.Point3f(*(dr.opaque(mi.Float, float(v)) for v in pose[:3, 3]))
    d = prep.directions
    d_world = mi.Vector3f(
        *(rot[i][0] * d.x + rot[i][1] * d.y + rot[i][2] * d.z for i in range(3))
    )
    return mi.Ray3f(origin, d_world), origin


def lut_lookup(handle: SceneHandle, re, im, mat, cos_t, active, size: int):
    """Linear interpolation of per-material complex tables sampled over cos in [0, 1]."""
    mi, dr = handle.mi, handle.dr
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


def intersect(handle: SceneHandle, ray, active, skip_obj):
    """Closest hit; a ray inside a transmitting slab (``skip_obj``) ignores that object's
    faces once (its back face: the slab is the whole object)."""
    mi, dr = handle.mi, handle.dr
    si = handle.scene.ray_intersect(ray, active)
    if skip_obj is None:
        return si
    obj = dr.gather(mi.UInt32, handle.face_object, si.prim_index, active & si.is_valid())
    again = active & si.is_valid() & (obj == skip_obj)
    si2 = handle.scene.ray_intersect(si.spawn_ray(ray.d), again)
    return dr.select(again, si2, si)


def return_leg(handle: SceneHandle, si, candidate, radar_pos, prep: Prepared,
               fields=None):
    """Gain of the way back from ``si`` to the radar through slab materials.

    Returns ``(tau_re, tau_im, visible, arrival, n_slabs, fields)``: each transmissive
    object on the line multiplies ``tau`` by its ``T`` (both faces of one object count
    once), any other surface (or more than :data:`MAX_RETURN_SLABS` slabs) blocks. With
    ``prep.polarized``, ``fields`` (a list of complex field vectors ``(re, im)``) pass each
    slab through its TE/TM transmission instead and ``tau`` stays 1.
    """
    mi, dr = handle.mi, handle.dr
    tau_re = dr.full(mi.Float, 1.0, dr.width(candidate))
    tau_im = dr.zeros(mi.Float, dr.width(candidate))
    n_slabs = dr.zeros(mi.UInt32, dr.width(candidate))
    arrival = mi.Point3f(si.p)
    visible = mi.Bool(candidate)
    pending = mi.Bool(candidate)
    ray = si.spawn_ray_to(radar_pos)
    for step in range(MAX_RETURN_SLABS + 1):
        sb = handle.scene.ray_intersect(ray, pending)
        blocked = pending & sb.is_valid()
        if step == MAX_RETURN_SLABS:
            visible &= ~blocked
            break
        mat = dr.gather(mi.UInt32, handle.face_material, sb.prim_index, blocked)
        obj = dr.gather(mi.UInt32, handle.face_object, sb.prim_index, blocked)
        u = dr.normalize(ray.d)
        cos_b = dr.abs(dr.dot(u, sb.n))
        if prep.polarized:
            te = lut_lookup(handle, prep.pol_t[0], prep.pol_t[1], mat, cos_b, blocked,
                            FRESNEL_LUT_SIZE)
            tm = lut_lookup(handle, prep.pol_t[2], prep.pol_t[3], mat, cos_b, blocked,
                            FRESNEL_LUT_SIZE)
            through = blocked & ((te[0] * te[0] + te[1] * te[1]
                                  + tm[0] * tm[0] + tm[1] * tm[1]) > 0.0)
            s_b = te_basis(mi, dr, u, sb.n)
            fields = [tuple(dr.select(through, new, old) for new, old in zip(
                jones(dr, f, s_b, u, u, te, tm), f, strict=True)) for f in fields]
        else:
            t_re, t_im = lut_lookup(handle, prep.t_re, prep.t_im, mat, cos_b, blocked,
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
        sb2 = handle.scene.ray_intersect(ray2, through)
        obj2 = dr.gather(mi.UInt32, handle.face_object, sb2.prim_index,
                         through & sb2.is_valid())
        same = through & sb2.is_valid() & (obj2 == obj)
        arrival = dr.select(through, dr.select(same, sb2.p, sb.p), arrival)
        ray = dr.select(same, sb2.spawn_ray_to(radar_pos), ray2)
        pending = through
    return tau_re, tau_im, visible, arrival, n_slabs, fields


def interactions(
    handle: SceneHandle, radar: RadarConfig, pose: np.ndarray, prep: Prepared, hits
) -> Iterator[Interaction]:
    """THE bounce loop: yield what every ray's interaction sends back, bounce by bounce.

    State (ray, carry, path, ...) is evaluated at the start of each following bounce, in
    one kernel with whatever the consumer scheduled or scattered in between.
    ``hits`` (UInt32, max_bounces) counts the rays that hit something per bounce.
    """
    mi, dr = handle.mi, handle.dr
    ray, radar_pos = primary_rays(handle, prep, pose)
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
        e0 = antenna_polarization(dr, ray.d, up, prep.slant)
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

    def power(c):  # |C|^2 per ray (squared_norm of a scalar Float would sum over the rays)
        if prep.polarized:
            return dr.squared_norm(c[0]) + dr.squared_norm(c[1])
        return c[0] * c[0] + c[1] * c[1]

    for bounce in range(radar.max_bounces):
        if bounce > 0:
            state = [ray, prev_hit, departure, *carry, path_in, active, hits]
            if prep.transmits:
                state += [skip_obj, *carry_d]
            dr.eval(*state)
        si = intersect(handle, ray, active, skip_obj if bounce > 0 else None)
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
        mat = dr.gather(mi.UInt32, handle.face_material, si.prim_index, valid)
        s_coef = dr.gather(mi.Float, prep.s_coef, mat, valid)
        spec = dr.gather(mi.Float, prep.spec_coef, mat, valid)
        reflected = ray.d + 2.0 * cos_in * normal
        if prep.polarized:
            # the field sent back toward the radar, TE/TM on this surface (returns.py)
            r_te = lut_lookup(handle, prep.pol_r[0], prep.pol_r[1], mat, cos_in, valid,
                              FRESNEL_LUT_SIZE)
            r_tm = lut_lookup(handle, prep.pol_r[2], prep.pol_r[3], mat, cos_in, valid,
                              FRESNEL_LUT_SIZE)
            s_vec = te_basis(mi, dr, ray.d, normal)
            fields = [jones(dr, carry, s_vec, ray.d, u_out, r_te, r_tm)]
            if prep.transmits:
                fields.append(jones(dr, carry_d, s_vec, ray.d, u_out, r_te, r_tm))
        n_ret = mi.UInt32(0)
        tau = None
        if bounce > 0:
            if prep.transmits:
                tau_re, tau_im, visible, arrival, n_ret, fields_out = return_leg(
                    handle, si, visible, radar_pos, prep, fields if prep.polarized else None)
                if prep.polarized:
                    fields = fields_out
                else:
                    tau = (tau_re, tau_im)
            else:
                visible &= ~handle.scene.ray_test(si.spawn_ray_to(radar_pos), visible)

        if prep.polarized:  # received: the RX antenna's polarisation . field
            e_rx = antenna_polarization(dr, -u_out, up, prep.slant)
            cg = (dr.dot(e_rx, fields[0][0]), dr.dot(e_rx, fields[0][1]))
            cd = (dr.dot(e_rx, fields[-1][0]), dr.dot(e_rx, fields[-1][1])) \
                if prep.transmits else cg
        else:
            gamma = lut_lookup(handle, prep.lut_re, prep.lut_im, mat, cos_in, valid,
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
            f_norm = lut_lookup(handle, prep.dir_lut, None, mat, cos_in, valid, DIRECTIVE_LUT_SIZE)
            x = dr.maximum(0.5 * (1.0 + dr.dot(u_out, reflected)), 1e-30)
            pattern = dr.exp(alpha * dr.log(x)) / f_norm
        else:
            pattern = dr.maximum(cos_out, 0.0) / math.pi
        amp_d = s_coef * dr.sqrt(d_omega * pattern) / r_out
        amp_d = dr.select(visible, amp_d, 0.0)
        u = prep.diffuse_u + bounce * GOLDEN
        sin_d, cos_d = dr.sincos(-2.0 * math.pi * (u - dr.floor(u)))

        record = Interaction(
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
                    t_te = lut_lookup(handle, prep.pol_t[0], prep.pol_t[1], mat, cos_in, valid,
                                      FRESNEL_LUT_SIZE)
                    t_tm = lut_lookup(handle, prep.pol_t[2], prep.pol_t[3], mat, cos_in, valid,
                                      FRESNEL_LUT_SIZE)
                    t_op = ("jones", (s_vec, ray.d, ray.d, t_te, t_tm), None)
                    e2 = dr.maximum(power(carry), 1e-30)
                    q = transmit_probability(
                        power(apply_interaction(dr, carry, r_op)) / e2,
                        power(apply_interaction(dr, carry, t_op)) / e2)
                else:
                    t_c = lut_lookup(handle, prep.t_re, prep.t_im, mat, cos_in, valid,
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
                    apply_interaction(dr, carry, r_op), apply_interaction(dr, carry, t_op),
                    strict=True))
                carry_d = tuple(dr.select(reflect, a, b) * k_d for a, b in zip(
                    apply_interaction(dr, carry_d, r_op),
                    apply_interaction(dr, carry_d, t_op), strict=True))
                direction = dr.select(reflect, reflected, ray.d)
                obj = dr.gather(mi.UInt32, handle.face_object, si.prim_index, valid)
                skip_obj = dr.select(reflect, mi.UInt32(NO_OBJECT), obj)
            else:
                carry = apply_interaction(dr, carry, r_op)
                carry_d = carry
            ray = si.spawn_ray(direction)
            prev_hit = hit
            strength = power(carry)
            if prep.transmits:
                strength = dr.maximum(strength, power(carry_d))
            active = valid & (strength > 1e-10)
        yield record
