"""The per-ray return model shared by the Dr.Jit tracer and its NumPy reference.

Each ray of the grid represents a cone of solid angle ``dOmega`` [sr]. At every interaction
(up to ``max_bounces``) the hit patch sends a return to the radar made of two terms, after the
effective-roughness (ER) split of Degli-Esposti et al. (IEEE TAP 55(1), 2007): a fraction
``1 - S^2`` of the reflected power stays specular, ``S^2`` is scattered diffusely.

Field normalisation: a point source ``e^{-jkr}/r`` at the radar; the received value ``a`` is
scaled so that ``|a|^2 = sigma / (4 pi r^4)`` for a monostatic target of RCS ``sigma`` [m^2]
at range ``r`` (power relative to the transmit power and unit-gain antennas, times
``(4 pi)^2 / lambda^2``). Intensities are reported as ``10 log10(4 pi |a|^2)`` [dB], i.e.
RCS [dBsm] minus ``40 log10(range)``.

1. **Specular / physical-optics term** (Knott, *Radar Cross Section*, 2nd ed., §5.2: PO
   surface integral ``a = (j/lambda) int Gamma (cos t_i + cos t_o)/2 e^{-jkL}/(r_i r_o) dA``)
   sampled by the rays: the patch a ray hits has ``dA = r_i^2 dOmega / cos t_i``, so::

       a_c = (j / lambda) * C * Gamma(t_i) * sqrt(1 - S^2) * dOmega
             * (cos t_i + cos t_o) / (2 cos t_i) * (r_i / r_o) * w * e^{-jk(r_i + r_o)}

   with ``r_i`` the unfolded path from the radar (through earlier bounces) to the hit,
   ``r_o`` the hit-to-radar distance, ``C`` the product of earlier specular factors.
   Monostatic (first bounce) this is ``(j/lambda) Gamma dOmega e^{-2jkr}``; summed over a
   flat plate facing the radar it gives ``|a|^2 = A^2 / (lambda^2 r^4)``, i.e. the plate RCS
   ``4 pi A^2 / lambda^2``. Coherent summation thus produces the specular lobe, the
   dihedral/corner retro-reflection and the weak return of a smooth surface seen at an angle.
   ``w`` is a sampling (Nyquist) window: where the PO phase changes by more than ``pi``
   between neighbouring rays the sampled sum would alias into spurious clutter; the true
   integral cancels there (stationary phase), so those samples are tapered to zero::

       dphi = k |P_t (d_in - u_out)| r_i dTheta / cos t_i     (phase step per ray [rad])
       w = 1 for dphi <= pi/2, cos^2 taper to 0 at dphi = pi

2. **Diffuse (Lambertian) term**: the cone delivers power ``dOmega |C|^2`` to the patch,
   which re-radiates ``S^2 |Gamma|^2`` of it with a Lambertian pattern (``cos t_o / pi``)::

       |a_d|^2 = S^2 |C Gamma|^2 dOmega cos t_o / (pi r_o^2)

   with a pseudo-random phase on top of ``-k (r_i + r_o)`` (rough-surface speckle).

3. **Specular continuation** for the next bounce: ``C <- C * Gamma * sqrt(1 - S^2)``,
   direction mirrored about the normal. Later returns must see the radar (shadow ray).

``Gamma`` is the unpolarised Fresnel coefficient of :func:`sim2radar.em.unpolarized_reflection`
(half-space, ITU-R P.2040-3 eq. (31)): ``|Gamma|^2`` = mean of TE and TM power, phase of TE.
Range = half the path ``(r_i + r_o) / 2``; angle = direction from the radar to the last hit.
"""

from __future__ import annotations

import math

import numpy as np

from sim2radar.em import unpolarized_reflection

__all__ = [
    "FRESNEL_LUT_SIZE",
    "GOLDEN",
    "MIN_COS",
    "diffuse_phase_seed",
    "fresnel_lut",
    "nyquist_window",
    "ray_grid",
]

#: Samples of the Fresnel look-up table over cos(theta) in [0, 1].
FRESNEL_LUT_SIZE = 1025
#: Golden-ratio offset that decorrelates the diffuse phase between bounces.
GOLDEN = 0.6180339887498949
#: Floor on cos(theta_in) in the obliquity factors (avoids 1/0 at exact grazing).
MIN_COS = 0.02


def fresnel_lut(
    materials: list[str],
    frequency_hz: float,
    size: int = FRESNEL_LUT_SIZE,
    thickness_m: list[float | None] | None = None,
) -> np.ndarray:
    """Unpolarised Fresnel coefficient tables, sampled uniformly in ``cos(theta)``.

    Parameters
    ----------
    materials : list of str
    frequency_hz : float [Hz]
    size : int — samples over cos(theta) in [0, 1].
    thickness_m : list of (float or None), optional
        Per material: slab thickness [m] (ITU-R P.2040-3 §3) or ``None`` for a half-space.

    Returns
    -------
    (len(materials), size) complex128 — ``Gamma`` at ``cos(theta) = i / (size - 1)``.
    """
    cos_t = np.linspace(0.0, 1.0, size)
    theta = np.arccos(np.clip(cos_t, 0.0, 1.0))
    thickness = thickness_m or [None] * len(materials)
    return np.stack(
        [
            unpolarized_reflection(m, frequency_hz, theta, d)
            for m, d in zip(materials, thickness, strict=True)
        ]
    )


def diffuse_phase_seed(n_rays: int, seed: int | None) -> np.ndarray:
    """(n_rays,) float64 in [0, 1): per-ray speckle phase fraction; bounce ``k`` uses
    ``frac(u + k * 0.618...)`` (golden-ratio decorrelation)."""
    rng = np.random.default_rng(0x5EED if seed is None else int(seed) + 1)
    return rng.random(n_rays)


def nyquist_window(dphi: np.ndarray) -> np.ndarray:
    """Taper for the PO samples: 1 below ``pi/2`` phase step, cos^2 roll-off to 0 at ``pi``."""
    x = np.clip((np.asarray(dphi) - 0.5 * math.pi) / (0.5 * math.pi), 0.0, 1.0)
    return np.cos(0.5 * math.pi * x) ** 2


def ray_grid(
    azimuth_fov_rad: float,
    elevation_fov_rad: float,
    spacing_rad: float,
    *,
    seed: int | None = None,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Ray directions over the field of view on a regular azimuth/elevation grid.

    Parameters
    ----------
    azimuth_fov_rad, elevation_fov_rad : float
        Full FOV [rad].
    spacing_rad : float
        Nominal grid spacing [rad]; the actual spacing divides the FOV evenly.
    seed : int, optional
        If given, each ray is jittered uniformly within its grid cell (stratified sampling).

    Returns
    -------
    directions : (N, 3) float64 — unit vectors in the radar frame (x fwd, y left, z up).
    solid_angle_sr : (N,) float64 — ``cos(el) d_az d_el`` per ray [sr].
    spacing_rad : float — the geometric-mean grid spacing actually used [rad].
    """
    n_az = max(1, math.ceil(azimuth_fov_rad / spacing_rad - 1e-9))
    n_el = max(1, math.ceil(elevation_fov_rad / spacing_rad - 1e-9))
    d_az = azimuth_fov_rad / n_az
    d_el = elevation_fov_rad / n_el
    az = -0.5 * azimuth_fov_rad + (np.arange(n_az) + 0.5) * d_az
    el = -0.5 * elevation_fov_rad + (np.arange(n_el) + 0.5) * d_el
    az_g, el_g = np.meshgrid(az, el, indexing="ij")
    az_g = az_g.ravel()
    el_g = el_g.ravel()
    if seed is not None:
        rng = np.random.default_rng(seed)
        az_g = az_g + (rng.random(az_g.shape) - 0.5) * d_az
        el_g = el_g + (rng.random(el_g.shape) - 0.5) * d_el
    cos_el = np.cos(el_g)
    directions = np.stack([cos_el * np.cos(az_g), cos_el * np.sin(az_g), np.sin(el_g)], axis=1)
    solid_angle = cos_el * d_az * d_el
    return directions, solid_angle, math.sqrt(d_az * d_el)
