"""What the radar ray tracer puts on the device per radar config and seed, before tracing.

:func:`material_tables` builds the per-material tables of a config (Fresnel reflection, the
scattering coefficient and lobes, slab transmission, polarised TE/TM) and the receiver's IF
response per range bin once per config;
:func:`prepare_rays` adds a seed's ray grid (directions and solid angles made on the device),
speckle phases and reflect-or-transmit draws. Together they are a :class:`Prepared`, which
:class:`~sim2radar.radar.raytrace.RadarScene` caches per (config, seed) and its bounce loop
(:mod:`sim2radar.radar.raytrace_bounces`) reads. The tables and draws themselves are defined in
:mod:`sim2radar.radar.returns`.

``mi`` and ``dr`` are the ``mitsuba`` and ``drjit`` modules with the tracer's variant set
(passed in, so that importing this module stays cheap).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim2radar.hardware import to_drjit
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.receiver import range_bin_gain
from sim2radar.radar.returns import (
    continuation_uniforms,
    diffuse_phase_seed,
    directive_lut,
    fresnel_lut,
    polarized_luts,
    ray_angles,
    transmission_lut,
)

__all__ = ["Prepared", "material_tables", "prepare_rays"]


@dataclasses.dataclass
class Prepared:
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
    if_re: object = None  # IF response per true range bin (receiver.range_bin_gain)
    if_im: object = None


def material_tables(mi, materials: list[str], radar: RadarConfig) -> dict:
    """Per-material device tables of a config (Fresnel, roughness, lobes, transmission,
    polarised TE/TM) for the scene's ``materials`` (normalised names,
    :func:`~sim2radar.radar.raytrace_mesh.merge_meshes`): the :class:`Prepared` fields that no
    seed changes."""
    sc = radar.scattering
    thickness = [sc.thickness_m(m) for m in materials]
    lut = fresnel_lut(materials, radar.center_frequency_hz, thickness_m=thickness)
    lut = lut.astype(np.complex64)
    s = np.array([sc.coefficient(m) for m in materials], dtype=np.float32)
    directive = sc.model == "directive"
    alpha = dir_lut = None
    if directive:
        alphas = [sc.lobe(m) for m in materials]
        alpha = to_drjit(mi.Float, alphas, np.float32)
        dir_lut = to_drjit(mi.Float, directive_lut(alphas).ravel(), np.float32)
    transmits = any(sc.transmits(m) for m in materials)
    t_re = t_im = None
    if transmits:
        tl = transmission_lut(
            materials,
            radar.center_frequency_hz,
            [d if sc.transmits(m) else None for m, d in zip(materials, thickness, strict=True)],
        ).astype(np.complex64)
        t_re, t_im = to_drjit(mi.Float, tl.real.ravel()), to_drjit(mi.Float, tl.imag.ravel())
    pol_r = pol_t = None
    polarized = radar.hardware.polarization != "unpolarized"
    if polarized:
        refl, trans = polarized_luts(materials, radar.center_frequency_hz, thickness,
                                     [sc.transmits(m) for m in materials])

        def tables(table: np.ndarray) -> tuple:
            table = table.astype(np.complex64)
            return tuple(to_drjit(mi.Float, part(table[:, :, k]).ravel())
                         for k in (0, 1) for part in (np.real, np.imag))

        pol_r, pol_t = tables(refl), tables(trans)
    slant = math.radians(90.0 if radar.hardware.polarization == "horizontal" else 0.0)
    if_gain = range_bin_gain(radar).astype(np.complex64)
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
        "if_re": to_drjit(mi.Float, if_gain.real),
        "if_im": to_drjit(mi.Float, if_gain.imag),
    }


def prepare_rays(mi, dr, radar: RadarConfig, seed: int | None, tables: dict) -> Prepared:
    """The device arrays of one (config, seed): the seed's ray grid, speckle phases and
    reflect-or-transmit draws over the config's material ``tables`` (:func:`material_tables`)."""
    # ray_grid's rays, their directions and solid angles made on the device
    az, el, d_az, d_el = ray_angles(radar.azimuth_fov_rad, radar.elevation_fov_rad,
                                    math.radians(radar.ray_spacing_deg), seed=seed)
    n = len(az)
    az_d, el_d = to_drjit(mi.Float, az, np.float32), to_drjit(mi.Float, el, np.float32)
    sin_az, cos_az = dr.sincos(az_d)
    sin_el, cos_el = dr.sincos(el_d)
    directions = mi.Vector3f(cos_el * cos_az, cos_el * sin_az, sin_el)
    solid_angle = cos_el * (d_az * d_el)
    dr.eval(directions, solid_angle)
    choice = None
    if tables["transmits"]:
        draws = continuation_uniforms(n, radar.max_bounces, seed)
        choice = [to_drjit(mi.Float, row, np.float32) for row in draws]
    return Prepared(
        directions=directions,
        n_rays=n,
        solid_angle=solid_angle,
        diffuse_u=to_drjit(mi.Float, diffuse_phase_seed(n, seed), np.float32),
        spacing_rad=math.sqrt(d_az * d_el),
        choice_u=choice,
        **tables,
    )
