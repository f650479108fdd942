"""NumPy reference twin of the Dr.Jit radar tracer (small scenes only: O(rays x triangles)).

Brute-force Möller–Trumbore ray–triangle intersection and the return model of
:mod:`sim2radar.radar.returns` evaluated in float64 with the exact Fresnel / slab coefficients
and the exact directive-lobe normalisation (no look-up tables), bounce by bounce like
:func:`sim2radar.radar.raytrace_bounces.interactions`: :func:`reference_interactions` yields
per-bounce NumPy records,
:func:`reference_trace` weights them by the elements' two-way gain and bins them with
:func:`sim2radar.radar.binning.deposit`,
:func:`reference_paths` keeps them as paths.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from sim2radar.em import unpolarized_reflection, unpolarized_transmission
from sim2radar.radar.binning import Accumulator, deposit, direction_cosines
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.link_budget import two_way_pattern_gain
from sim2radar.radar.paths import PATH_KINDS
from sim2radar.radar.raytrace import check_pose, face_object_ids, merge_meshes
from sim2radar.radar.returns import (
    GOLDEN,
    MAX_RETURN_SLABS,
    MIN_COS,
    continuation_uniforms,
    diffuse_phase_seed,
    directive_lobe,
    directive_normalisation,
    nyquist_window,
    ray_grid,
    transmit_probability,
)

EPS_M = 1e-5  # origin offset of spawned rays [m]


def intersect(orig: np.ndarray, dirs: np.ndarray, tris: np.ndarray, eps: float = 1e-9):
    """Closest hit of each ray (Möller & Trumbore 1997): (t, face), t = inf for misses."""
    v0, v1, v2 = tris[:, 0], tris[:, 1], tris[:, 2]
    e1, e2 = v1 - v0, v2 - v0  # (F, 3)
    pvec = np.cross(dirs[:, None, :], e2[None])  # (N, F, 3)
    det = np.einsum("nfk,fk->nf", pvec, e1)
    inv = 1.0 / np.where(np.abs(det) < eps, np.inf, det)
    tvec = orig[:, None, :] - v0[None]
    u = np.einsum("nfk,nfk->nf", tvec, pvec) * inv
    qvec = np.cross(tvec, e1[None])
    v = np.einsum("nk,nfk->nf", dirs, qvec) * inv
    t = np.einsum("fk,nfk->nf", e2, qvec) * inv
    ok = (np.abs(det) >= eps) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)
    t = np.where(ok, t, np.inf)
    face = np.argmin(t, axis=1)
    return t[np.arange(len(t)), face], face


class _Scene:
    """Triangles, normals, per-face material and object of a mesh list (float64)."""

    def __init__(self, meshes) -> None:
        vertices, faces, self.face_mat, self.materials = merge_meshes(meshes)
        self.face_obj = face_object_ids(meshes).astype(np.int64)
        self.tris = vertices.astype(np.float64)[faces.astype(np.int64)]
        n = np.cross(self.tris[:, 1] - self.tris[:, 0], self.tris[:, 2] - self.tris[:, 0])
        self.normals = n / np.linalg.norm(n, axis=1, keepdims=True)

    def hit(self, o, d, active, skip=None):
        """(t, face, valid) from origins ``o`` along unit ``d``; rays inside object ``skip``
        (>= 0) ignore its first face (the slab's back face)."""
        t = np.full(len(d), np.inf)
        face = np.zeros(len(d), dtype=np.int64)
        if active.any():
            t[active], face[active] = intersect(o[active], d[active], self.tris)
        valid = active & np.isfinite(t)
        if skip is not None:
            again = valid & (skip >= 0) & (self.face_obj[face] == skip)
            if again.any():
                o2 = o[again] + (t[again, None] + EPS_M) * d[again]
                t2, f2 = intersect(o2, d[again], self.tris)
                t[again] = np.where(np.isfinite(t2), t[again] + EPS_M + t2, np.inf)
                face[again] = f2
                valid = active & np.isfinite(t)
        return t, face, valid


def _gamma(radar: RadarConfig, materials, mat, cos_t, sel, kind: str) -> np.ndarray:
    """Exact unpolarised reflection (``kind="r"``) or slab transmission (``"t"``) per ray."""
    out = np.zeros(len(mat), dtype=np.complex128)
    theta = np.arccos(np.clip(cos_t, 0.0, 1.0))
    for m_i, name in enumerate(materials):
        s = sel & (mat == m_i)
        if not s.any():
            continue
        d = radar.scattering.thickness_m(name)
        if kind == "r":
            out[s] = unpolarized_reflection(name, radar.center_frequency_hz, theta[s], d)
        elif radar.scattering.transmits(name):
            out[s] = unpolarized_transmission(name, radar.center_frequency_hz, theta[s], d)
    return out


def _return_leg(scene: _Scene, radar: RadarConfig, hit, normal, radar_pos, visible):
    """``tau``, visibility, arrival point and slab count of the way back (returns.py item 4)."""
    n = len(hit)
    tau = np.ones(n, dtype=np.complex128)
    n_slabs = np.zeros(n, dtype=np.int64)
    arrival = hit.copy()
    visible = visible.copy()
    origin = hit + EPS_M * normal
    pending = visible.copy()
    for step in range(MAX_RETURN_SLABS + 1):
        to_r = radar_pos - origin
        dist = np.linalg.norm(to_r, axis=1)
        d = to_r / np.maximum(dist, 1e-12)[:, None]
        t, face, valid = scene.hit(origin, d, pending)
        blocked = valid & (t < dist - 2 * EPS_M)
        if step == MAX_RETURN_SLABS:
            visible &= ~blocked
            break
        mat = scene.face_mat[face]
        cos_b = np.abs(np.einsum("nk,nk->n", d, scene.normals[face]))
        t_b = _gamma(radar, scene.materials, mat, cos_b, blocked, "t")
        through = blocked & (np.abs(t_b) > 0)
        visible &= ~(blocked & ~through)
        tau = np.where(through, tau * t_b, tau)
        n_slabs += through
        cross = origin + t[:, None] * d
        # step past the same object's other face
        o2 = cross + EPS_M * d
        t2, f2, v2 = scene.hit(o2, d, through)
        same = through & v2 & (t2 < np.linalg.norm(radar_pos - o2, axis=1)) & (
            scene.face_obj[f2] == scene.face_obj[face]
        )
        exit_p = np.where(same[:, None], o2 + t2[:, None] * d, cross)
        arrival = np.where(through[:, None], exit_p, arrival)
        origin = np.where(through[:, None], exit_p + EPS_M * d, origin)
        pending = through
    return tau, visible, arrival, n_slabs


def reference_interactions(
    meshes, radar: RadarConfig, pose=None, seed: int | None = None
) -> Iterator[dict]:
    """Per-bounce NumPy records (world frame) of every ray, like
    :func:`sim2radar.radar.raytrace_bounces.interactions`."""
    pose = check_pose(pose)
    scene = _Scene(meshes)
    sc = radar.scattering
    materials = scene.materials
    s_tab = np.array([sc.coefficient(m) for m in materials])
    spec_tab = np.sqrt(1.0 - s_tab**2)
    alpha_tab = np.array([sc.lobe(m) for m in materials])
    transmits = any(sc.transmits(m) for m in materials)
    k = 2.0 * math.pi / radar.wavelength_m

    dirs_r, d_omega, spacing = ray_grid(
        radar.azimuth_fov_rad, radar.elevation_fov_rad, math.radians(radar.ray_spacing_deg),
        seed=seed,
    )
    n = len(dirs_r)
    u_seed = diffuse_phase_seed(n, seed)
    choice = continuation_uniforms(n, radar.max_bounces, seed) if transmits else None
    rot, radar_pos = pose[:3, :3], pose[:3, 3]
    d = dirs_r @ rot.T
    o = np.broadcast_to(radar_pos, d.shape).copy()
    carry = np.ones(n, dtype=np.complex128)
    carry_d = np.ones(n, dtype=np.complex128)
    path_in = np.zeros(n)
    active = np.ones(n, dtype=bool)
    departure = np.zeros((n, 3))
    prev_hit = np.broadcast_to(radar_pos, d.shape).copy()
    skip = np.full(n, -1, dtype=np.int64)
    for bounce in range(radar.max_bounces):
        t, face, valid = scene.hit(o, d, active, skip if bounce > 0 else None)
        t = np.where(valid, t, 0.0)
        nrm = scene.normals[face]
        cos_in = -np.einsum("nk,nk->n", d, nrm)
        nrm = np.where((cos_in < 0)[:, None], -nrm, nrm)
        cos_in = np.abs(cos_in)
        hit = o + t[:, None] * d
        if bounce == 0:
            departure = hit.copy()
        # the unfolded path runs through the true hit points (not the offset origins)
        path_in = path_in + np.where(valid, np.linalg.norm(hit - prev_hit, axis=1), 0.0)
        to_radar = radar_pos - hit
        r_out = np.linalg.norm(to_radar, axis=1)
        u_out = to_radar / np.maximum(r_out, 1e-12)[:, None]
        cos_out = np.einsum("nk,nk->n", u_out, nrm)
        visible = valid & (cos_out > 0)
        tau = np.ones(n, dtype=np.complex128)
        arrival = hit.copy()
        n_ret = np.zeros(n, dtype=np.int64)
        if bounce > 0:
            if transmits:
                tau, visible, arrival, n_ret = _return_leg(scene, radar, hit, nrm, radar_pos,
                                                           visible)
            else:
                t_sh, _, v_sh = scene.hit(hit + EPS_M * nrm, u_out, visible)
                visible &= ~(v_sh & (t_sh < r_out - 2 * EPS_M))
        mat = scene.face_mat[face]
        gamma = _gamma(radar, materials, mat, cos_in, valid, "r")
        spec_f = spec_tab[mat]
        cg = carry * gamma * tau
        cd = carry_d * gamma * tau
        ci = np.maximum(cos_in, MIN_COS)
        grad = d - u_out
        grad_t = grad - np.einsum("nk,nk->n", grad, nrm)[:, None] * nrm
        dphi = k * np.linalg.norm(grad_t, axis=1) * path_in * spacing / ci
        amp_c = (
            spec_f * d_omega * (cos_in + cos_out) / (2 * ci) * (path_in / np.maximum(r_out, 1e-12))
            * nyquist_window(dphi) / radar.wavelength_m
        )
        reflected = d + 2 * cos_in[:, None] * nrm
        if sc.model == "directive":
            pattern = np.zeros(n)
            for m_i in range(len(materials)):
                sel = valid & (mat == m_i)
                if sel.any():
                    lobe = directive_lobe(np.einsum("nk,nk->n", u_out[sel], reflected[sel]),
                                          alpha_tab[m_i])
                    pattern[sel] = lobe / directive_normalisation(cos_in[sel], alpha_tab[m_i])
        else:
            pattern = np.maximum(cos_out, 0.0) / math.pi
        amp_d = s_tab[mat] * np.sqrt(d_omega * pattern) / np.maximum(r_out, 1e-12)
        uu = u_seed + bounce * GOLDEN
        spec = np.where(visible, 1j * cg * amp_c, 0.0)
        diff = np.where(visible, cd * amp_d * np.exp(-2j * math.pi * (uu - np.floor(uu))), 0.0)
        yield {
            "bounce": bounce,
            "valid": valid,
            "visible": visible,
            "hit": hit,
            "arrival": arrival,
            "departure": departure,
            "path_m": path_in + r_out,
            "spec": spec,
            "diff": diff,
            "n_interactions": bounce + 1 + n_ret,
        }
        # continuation
        f = gamma * spec_f
        new_d = reflected
        f_d = f
        if transmits:
            t_c = _gamma(radar, materials, mat, cos_in, valid, "t")
            q = transmit_probability(np.abs(f) ** 2, np.abs(t_c) ** 2)
            reflect = choice[bounce] >= q
            w = np.where(reflect, 1.0 - q, q)
            b = np.where(reflect, f, t_c)
            f = b / np.maximum(w, 1e-30)
            f_d = b / np.sqrt(np.maximum(w, 1e-30))
            new_d = np.where(reflect[:, None], reflected, d)
            skip = np.where(reflect, -1, scene.face_obj[face])
        carry = carry * f
        carry_d = carry_d * f_d
        offset = np.where(np.einsum("nk,nk->n", new_d, nrm)[:, None] >= 0, nrm, -nrm)
        o = hit + EPS_M * offset
        prev_hit = hit
        d = new_d
        strength = np.maximum(np.abs(carry) ** 2, np.abs(carry_d) ** 2)
        active = valid & (strength > 1e-10)


def reference_trace(meshes, radar: RadarConfig, pose=None, seed: int | None = None) -> Accumulator:
    """The binning simulator's Accumulator, computed with NumPy in float64."""
    pose = check_pose(pose)
    k = 2.0 * math.pi / radar.wavelength_m
    cols: dict[str, list] = {"a": [], "r": [], "ua": [], "ue": []}
    for rec in reference_interactions(meshes, radar, pose, seed):
        vis = rec["visible"]
        a = (rec["spec"] + rec["diff"]) * np.exp(-1j * k * rec["path_m"])
        q = (rec["arrival"] - pose[:3, 3]) @ pose[:3, :3]
        dep = (rec["departure"] - pose[:3, 3]) @ pose[:3, :3]
        a = a * np.sqrt(two_way_pattern_gain(radar, dep, q))   # the elements' two-way gain
        _, ua, ue = direction_cosines(q)
        cols["a"].append(np.where(vis, a, 0.0))
        cols["r"].append(0.5 * rec["path_m"])
        cols["ua"].append(ua)
        cols["ue"].append(ue)
    cat = {key: np.concatenate(v) for key, v in cols.items()}
    return deposit(cat["r"], cat["ua"], cat["ue"], cat["a"], radar)


def reference_paths(meshes, radar: RadarConfig, pose=None, seed: int | None = None) -> dict:
    """Visible paths (radar frame, ray order per bounce), like ``RadarScene.trace_paths``
    without pruning: ``amplitude``, ``path_length_m``, ``departure_point_m``,
    ``arrival_point_m``, ``n_interactions``, ``kind``."""
    pose = check_pose(pose)
    rot, origin = pose[:3, :3], pose[:3, 3]
    out: dict[str, list] = {k: [] for k in ("amplitude", "path_length_m", "departure_point_m",
                                            "arrival_point_m", "n_interactions", "kind")}
    for rec in reference_interactions(meshes, radar, pose, seed):
        amp = rec["spec"] + rec["diff"]
        keep = rec["visible"] & (np.abs(amp) > 0)
        has_s, has_d = np.abs(rec["spec"]) > 0, np.abs(rec["diff"]) > 0
        kind = np.where(has_s & has_d, PATH_KINDS["mixed"],
                        np.where(has_s, PATH_KINDS["specular"], PATH_KINDS["diffuse"]))
        out["amplitude"].append(amp[keep])
        out["path_length_m"].append(rec["path_m"][keep])
        out["departure_point_m"].append((rec["departure"][keep] - origin) @ rot)
        out["arrival_point_m"].append((rec["arrival"][keep] - origin) @ rot)
        out["n_interactions"].append(np.broadcast_to(rec["n_interactions"], keep.shape)[keep])
        out["kind"].append(kind[keep])
    return {k: np.concatenate(v) for k, v in out.items()}
