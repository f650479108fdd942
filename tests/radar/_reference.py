"""NumPy reference twin of the Dr.Jit radar tracer (small scenes only: O(rays x triangles)).

Brute-force Möller–Trumbore ray–triangle intersection, the same return model as
:mod:`sim2radar.radar.returns` evaluated in float64 with the exact Fresnel coefficients
(no look-up table), the same binning via :func:`sim2radar.radar.binning.accumulate`.
"""

from __future__ import annotations

import math

import numpy as np

from sim2radar.em import unpolarized_reflection
from sim2radar.radar.binning import Accumulator, accumulate, bin_indices
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.raytrace import check_pose, merge_meshes
from sim2radar.radar.returns import GOLDEN, MIN_COS, diffuse_phase_seed, nyquist_window, ray_grid


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


def reference_trace(meshes, radar: RadarConfig, pose=None) -> Accumulator:
    """Accumulated returns of one frame, computed with NumPy in float64."""
    pose = check_pose(pose)
    vertices, faces, face_mat, materials = merge_meshes(meshes)
    tris = vertices.astype(np.float64)[faces.astype(np.int64)]
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    s_tab = np.array([radar.scattering.coefficient(m) for m in materials])
    spec_tab = np.sqrt(1.0 - s_tab**2)
    freq = radar.center_frequency_hz
    k = 2.0 * math.pi / radar.wavelength_m

    dirs_r, d_omega, spacing = ray_grid(
        radar.azimuth_fov_rad, radar.elevation_fov_rad, math.radians(radar.ray_spacing_deg)
    )
    u_seed = diffuse_phase_seed(len(dirs_r), None)
    rot, radar_pos = pose[:3, :3], pose[:3, 3]
    d = dirs_r @ rot.T
    o = np.broadcast_to(radar_pos, d.shape).copy()
    carry = np.ones(len(d), dtype=np.complex128)
    path_in = np.zeros(len(d))
    active = np.ones(len(d), dtype=bool)
    n_cells = radar.n_range_bins * radar.n_azimuth_bins * radar.n_elevation_bins
    parts = []
    for bounce in range(radar.max_bounces):
        t, face = intersect(o, d, tris)
        valid = active & np.isfinite(t)
        t = np.where(valid, t, 0.0)
        n = normals[face]
        cos_in = -np.einsum("nk,nk->n", d, n)
        n = np.where((cos_in < 0)[:, None], -n, n)
        cos_in = np.abs(cos_in)
        hit = o + t[:, None] * d
        path_in = path_in + t
        to_radar = radar_pos - hit
        r_out = np.linalg.norm(to_radar, axis=1)
        u_out = to_radar / np.maximum(r_out, 1e-12)[:, None]
        cos_out = np.einsum("nk,nk->n", u_out, n)
        visible = valid & (cos_out > 0)
        if bounce > 0:
            t_sh, _ = intersect(hit + 1e-5 * n, u_out, tris)
            visible &= ~(t_sh < r_out - 2e-5)
        mat = face_mat[face]
        gamma = np.zeros(len(d), dtype=np.complex128)
        for m_i, m_name in enumerate(materials):
            sel = valid & (mat == m_i)
            gamma[sel] = unpolarized_reflection(
                m_name,
                freq,
                np.arccos(np.clip(cos_in[sel], 0.0, 1.0)),
                radar.scattering.thickness_m(m_name),
            )
        s = s_tab[mat]
        spec = spec_tab[mat]
        cg = carry * gamma
        path = path_in + r_out
        ci = np.maximum(cos_in, MIN_COS)
        grad = d - u_out
        grad_t = grad - np.einsum("nk,nk->n", grad, n)[:, None] * n
        dphi = k * np.linalg.norm(grad_t, axis=1) * path_in * spacing / ci
        amp_c = (
            (spec * d_omega * (cos_in + cos_out) / (2 * ci) * (path_in / np.maximum(r_out, 1e-12)))
            * nyquist_window(dphi)
            / radar.wavelength_m
        )
        a = 1j * cg * amp_c * np.exp(-1j * k * path)
        amp_d = s * np.sqrt(d_omega * np.maximum(cos_out, 0) / math.pi) / np.maximum(r_out, 1e-12)
        uu = u_seed + bounce * GOLDEN
        a = a + cg * amp_d * np.exp(-1j * (k * path + 2 * math.pi * (uu - np.floor(uu))))
        q = (hit - radar_pos) @ rot
        az = np.arctan2(q[:, 1], q[:, 0])
        el = np.arctan2(q[:, 2], np.hypot(q[:, 0], q[:, 1]))
        rng_m = 0.5 * path
        idx = bin_indices(rng_m, az, el, radar)
        idx = np.where(visible, idx, -1)
        parts.append((idx, a, rng_m, az, el))
        carry = cg * spec
        d = d + 2 * cos_in[:, None] * n
        o = hit + 1e-5 * n
        active = valid & (np.abs(carry) ** 2 > 1e-10)
    cat = [np.concatenate([p[i] for p in parts]) for i in range(5)]
    return accumulate(*cat, n_cells=n_cells)
