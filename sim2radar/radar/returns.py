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
             * (cos t_i + cos t_o) / (2 cos t_i) * (r_i / r_o) * w * tau * e^{-jk(r_i + r_o)}

   with ``r_i`` the unfolded path from the radar (through earlier bounces) to the hit,
   ``r_o`` the hit-to-radar distance, ``C`` the product of earlier specular factors and
   ``tau`` the return leg's gain (below). Monostatic (first bounce) this is
   ``(j/lambda) Gamma dOmega e^{-2jkr}``; summed over a flat plate facing the radar it gives
   ``|a|^2 = A^2 / (lambda^2 r^4)``, i.e. the plate RCS ``4 pi A^2 / lambda^2``. Coherent
   summation thus produces the specular lobe, the dihedral/corner retro-reflection and the
   weak return of a smooth surface seen at an angle. ``w`` is a sampling (Nyquist) window:
   where the PO phase changes by more than ``pi`` between neighbouring rays the sampled sum
   would alias into spurious clutter; the true integral cancels there (stationary phase), so
   those samples are tapered to zero::

       dphi = k |P_t (d_in - u_out)| r_i dTheta / cos t_i     (phase step per ray [rad])
       w = 1 for dphi <= pi/2, cos^2 taper to 0 at dphi = pi

2. **Diffuse term**: the cone delivers power ``dOmega |C|^2`` to the patch, which re-radiates
   ``S^2 |Gamma|^2`` of it with a normalised pattern ``f_s`` (``int f_s dOmega_s = 1`` over the
   half-space in front of the patch)::

       |a_d|^2 = S^2 |C Gamma tau|^2 dOmega f_s / r_o^2

   with a pseudo-random phase on top of ``-k (r_i + r_o)`` (rough-surface speckle; ``C`` is
   the power-unbiased copy of item 3 when rays may pass through slabs).
   ``scattering.model`` picks ``f_s``:

   * ``lambertian``: ``f_s = cos t_o / pi``;
   * ``directive`` (Degli-Esposti et al. 2007, "directive model"):
     ``f_s = ((1 + cos psi_R) / 2)^alpha_R / F_alpha(t_i)``, ``psi_R`` the angle between the
     direction back to the radar and the specular direction, ``F_alpha`` the integral of the
     lobe over the half-space (closed form of the paper for integer ``alpha_R``,
     :func:`directive_normalisation`), so the total scattered power is ``S^2 |Gamma|^2`` of the
     incident power on the facet. Monostatic, ``cos psi_R = cos 2 t_i``: the backscatter falls
     as ``cos^{2 alpha_R} t_i``.

3. **Continuation** for the next bounce. Without transmission: specular,
   ``C <- C * Gamma * sqrt(1 - S^2)``, direction mirrored about the normal. With
   ``scattering.transmission`` and a slab material, one seeded choice per ray and interaction
   (:func:`continuation_uniforms`): pass straight through with the slab transmission
   coefficient ``T`` (ITU-R P.2040-3 eq. (43b)) with probability ``q``
   (:func:`transmit_probability`: ``|T|^2 / (|R|^2 + |T|^2)``, ``R = Gamma sqrt(1 - S^2)``,
   clipped to [0.1, 0.9] so no weight exceeds 10; branches below 1e-4 of the power are
   dropped), else reflect. The chosen factor is divided by the chosen branch's probability
   ``w`` in one copy of ``C`` and by ``sqrt(w)`` in a second one: with the first, each branch's
   expected contribution is exact in amplitude (right for the coherent physical-optics
   samples, whose sum over many rays would otherwise lose a factor ``sqrt(w)``), with the
   second exact in power (right for the incoherent diffuse samples). A
   transmitted ray ignores the back face of the object it entered (the slab of configured
   thickness is the whole object: a wall box has two faces but is one slab).

4. **Return leg** ``tau``: the first interaction sees the radar along its own ray (``tau =
   1``). Later ones need a clear line back: without transmission ``tau`` is 1 or 0 (shadow
   ray); with transmission each slab material on the way back multiplies ``tau`` by its ``T``
   (at most :data:`MAX_RETURN_SLABS` objects; anything else blocks).

``Gamma`` is the unpolarised Fresnel coefficient of :func:`sim2radar.em.unpolarized_reflection`
(half-space, ITU-R P.2040-3 eq. (31), or the slab of eq. (43a)): ``|Gamma|^2`` = mean of TE and
TM power, phase of TE; ``T`` likewise (:func:`sim2radar.em.unpolarized_transmission`).
Range = half the path ``(r_i + r_o) / 2``; the arrival direction is the direction from the
radar to the last interaction point (:mod:`sim2radar.radar.binning` turns it into the virtual
array's response).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from sim2radar.em import unpolarized_reflection, unpolarized_transmission

__all__ = [
    "DIRECTIVE_LUT_SIZE",
    "FRESNEL_LUT_SIZE",
    "GOLDEN",
    "MAX_RETURN_SLABS",
    "MIN_COS",
    "continuation_uniforms",
    "diffuse_phase_seed",
    "directive_lobe",
    "directive_lut",
    "directive_normalisation",
    "fresnel_lut",
    "nyquist_window",
    "polarized_luts",
    "ray_angles",
    "ray_grid",
    "transmission_lut",
    "transmit_probability",
]

#: Samples of the Fresnel look-up table over cos(theta) in [0, 1].
FRESNEL_LUT_SIZE = 1025
#: Golden-ratio offset that decorrelates the diffuse phase between bounces.
GOLDEN = 0.6180339887498949
#: Floor on cos(theta_in) in the obliquity factors (avoids 1/0 at exact grazing).
MIN_COS = 0.02
#: Samples of the directive-model normalisation table over cos(theta_i) in [0, 1].
DIRECTIVE_LUT_SIZE = 257
#: Slab objects a return leg may pass through before it counts as blocked (transmission on).
MAX_RETURN_SLABS = 2


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


def polarized_luts(
    materials: list[str],
    frequency_hz: float,
    thickness_m: list[float | None],
    transmits: list[bool],
    size: int = FRESNEL_LUT_SIZE,
) -> tuple[np.ndarray, np.ndarray]:
    """TE and TM reflection and transmission tables for the polarised tracer, sampled like
    :func:`fresnel_lut` (half-space ITU-R P.2040-3 eq. (31) or the slab of eqs. (43a)/(43b)).

    Parameters
    ----------
    materials : list of str
    frequency_hz : float [Hz]
    thickness_m : list of (float or None) — slab thickness [m] per material, or ``None``.
    transmits : list of bool — materials rays may pass through (zeros otherwise).
    size : int — samples over cos(theta) in [0, 1].

    Returns
    -------
    reflection : (len(materials), size, 2) complex128 — ``r_te``, ``r_tm``.
    transmission : (len(materials), size, 2) complex128 — ``t_te``, ``t_tm``.
    """
    from sim2radar.em import reflection_coefficients, transmission_coefficients

    cos_t = np.linspace(0.0, 1.0, size)
    theta = np.arccos(np.clip(cos_t, 0.0, 1.0))
    refl, trans = [], []
    for m, d, t in zip(materials, thickness_m, transmits, strict=True):
        refl.append(np.stack(reflection_coefficients(m, frequency_hz, theta, d), axis=-1))
        if t and d is not None:
            trans.append(np.stack(transmission_coefficients(m, frequency_hz, theta, d), axis=-1))
        else:
            trans.append(np.zeros((size, 2), dtype=np.complex128))
    return np.stack(refl), np.stack(trans)


def transmission_lut(
    materials: list[str],
    frequency_hz: float,
    thickness_m: list[float | None],
    size: int = FRESNEL_LUT_SIZE,
) -> np.ndarray:
    """Unpolarised slab transmission tables (ITU-R P.2040-3 eq. (43b)), like :func:`fresnel_lut`.

    Parameters
    ----------
    materials : list of str
    frequency_hz : float [Hz]
    thickness_m : list of (float or None)
        Per material: slab thickness [m], or ``None`` for an opaque material (zeros).
    size : int — samples over cos(theta) in [0, 1].

    Returns
    -------
    (len(materials), size) complex128 — ``T`` at ``cos(theta) = i / (size - 1)``.
    """
    cos_t = np.linspace(0.0, 1.0, size)
    theta = np.arccos(np.clip(cos_t, 0.0, 1.0))
    rows = []
    for m, d in zip(materials, thickness_m, strict=True):
        if d is None:
            rows.append(np.zeros(size, dtype=np.complex128))
        else:
            rows.append(unpolarized_transmission(m, frequency_hz, theta, d))
    return np.stack(rows)


def directive_lobe(cos_psi: np.ndarray, alpha: float | np.ndarray) -> np.ndarray:
    """Unnormalised directive lobe ``((1 + cos psi_R) / 2)^alpha_R`` [-] (Degli-Esposti et al.
    2007, directive model); ``psi_R`` = angle to the specular direction."""
    x = np.clip((1.0 + np.asarray(cos_psi, dtype=np.float64)) / 2.0, 0.0, 1.0)
    return x ** np.asarray(alpha, dtype=np.float64)


def _directive_normalisation_closed(cos_theta_i: np.ndarray, alpha: int) -> np.ndarray:
    """``F_alpha`` for integer ``alpha`` (Degli-Esposti et al. 2007, directive model)::

        F_alpha = 2^-alpha sum_{j=0}^{alpha} C(alpha, j) I_j
        I_j = 2 pi / (j + 1)                                                    (j even)
        I_j = 2 pi / (j + 1) cos t_i sum_{w=0}^{(j-1)/2} C(2w, w) sin^{2w} t_i / 2^{2w}  (j odd)
    """
    c = np.clip(np.asarray(cos_theta_i, dtype=np.float64), 0.0, 1.0)
    s2 = 1.0 - c**2
    total = np.zeros_like(c)
    for j in range(alpha + 1):
        if j % 2 == 0:
            i_j = np.full_like(c, 2.0 * math.pi / (j + 1))
        else:
            series = sum(math.comb(2 * w, w) * s2**w / 4.0**w for w in range((j - 1) // 2 + 1))
            i_j = 2.0 * math.pi / (j + 1) * c * series
        total += math.comb(alpha, j) * i_j
    return total / 2.0**alpha


def _directive_normalisation_numeric(
    cos_theta_i: np.ndarray, alpha: float, n_theta: int = 192, n_phi: int = 384
) -> np.ndarray:
    """``F_alpha`` by quadrature over the half-space in front of the facet (any ``alpha``):
    Gauss-Legendre in the scattering zenith angle, uniform (spectrally exact) in azimuth."""
    c = np.clip(np.asarray(cos_theta_i, dtype=np.float64), 0.0, 1.0).reshape(-1)
    x, w = np.polynomial.legendre.leggauss(n_theta)
    theta_s = 0.25 * math.pi * (x + 1.0)  # [0, pi/2]
    w_theta = 0.25 * math.pi * w * np.sin(theta_s)
    phi = (np.arange(n_phi) + 0.5) * (2.0 * math.pi / n_phi)
    s_i = np.sqrt(1.0 - c**2)
    out = np.empty_like(c)
    for k in range(len(c)):
        # specular direction at zenith t_i, azimuth 0; cos psi = k_r . k_s
        cos_psi = (s_i[k] * np.sin(theta_s)[:, None] * np.cos(phi)[None, :]
                   + c[k] * np.cos(theta_s)[:, None])
        out[k] = (directive_lobe(cos_psi, alpha) * w_theta[:, None]).sum() * (2.0 * math.pi / n_phi)
    return out.reshape(np.shape(cos_theta_i))


def directive_normalisation(cos_theta_i: np.ndarray, alpha: float) -> np.ndarray:
    """``F_alpha(t_i) = int ((1 + cos psi_R)/2)^alpha dOmega_s`` over the half-space in front of
    the facet [sr], for a lobe centred on the specular direction at incidence ``t_i``.

    Integer ``alpha``: the closed form of Degli-Esposti et al. (2007); otherwise numerical
    quadrature. ``F_0 = 2 pi``.
    """
    a = float(alpha)
    if a < 0 or not math.isfinite(a):
        raise ValueError(f"alpha_R must be >= 0, got {alpha}")
    if a == round(a) and a <= 200:
        return _directive_normalisation_closed(cos_theta_i, int(round(a)))
    return _directive_normalisation_numeric(cos_theta_i, a)


@functools.lru_cache(maxsize=64)
def _directive_row(alpha: float, size: int) -> np.ndarray:
    return directive_normalisation(np.linspace(0.0, 1.0, size), alpha)


def directive_lut(alphas: list[float], size: int = DIRECTIVE_LUT_SIZE) -> np.ndarray:
    """(len(alphas), size) float64 — ``F_alpha`` at ``cos(t_i) = i / (size - 1)`` [sr]."""
    return np.stack([_directive_row(float(a), size) for a in alphas])


#: Transmission probability bounds of :func:`transmit_probability` (defensive sampling).
TRANSMIT_PROBABILITY_RANGE = (0.1, 0.9)
#: Branches carrying less than this fraction of the power are not sampled.
NEGLIGIBLE_BRANCH = 1e-4


def transmit_probability(reflected_power, transmitted_power):
    """Probability of choosing transmission at a slab: ``|T|^2 / (|R|^2 + |T|^2)``, clipped to
    :data:`TRANSMIT_PROBABILITY_RANGE` (bounded weights); 0 (1) when transmission (reflection)
    carries under :data:`NEGLIGIBLE_BRANCH` of the power. Works on NumPy and Dr.Jit arrays.

    Parameters
    ----------
    reflected_power, transmitted_power : arrays — ``|R|^2``, ``|T|^2`` [-].
    """
    lo, hi = TRANSMIT_PROBABILITY_RANGE
    total = reflected_power + transmitted_power
    safe = total + (total <= 0) * 1.0  # avoids 0/0; both branches empty -> q = 0
    q = transmitted_power / safe
    clipped = q * 0.0 + lo + (q > lo) * (q - lo) - (q > hi) * (q - hi)  # clip(q, lo, hi)
    out = (q >= NEGLIGIBLE_BRANCH) * clipped
    return out + (q > 1.0 - NEGLIGIBLE_BRANCH) * (1.0 - out)


def continuation_uniforms(n_rays: int, n_bounces: int, seed: int | None) -> np.ndarray:
    """(n_bounces, n_rays) float64 in [0, 1): the reflect-or-transmit draws of each ray and
    interaction (seed ``None`` uses a fixed stream, so unseeded frames stay deterministic)."""
    rng = np.random.default_rng([0x7A5, 0 if seed is None else int(seed) + 1])
    return rng.random((n_bounces, n_rays))


def diffuse_phase_seed(n_rays: int, seed: int | None) -> np.ndarray:
    """(n_rays,) float64 in [0, 1): per-ray speckle phase fraction; bounce ``k`` uses
    ``frac(u + k * 0.618...)`` (golden-ratio decorrelation)."""
    rng = np.random.default_rng(0x5EED if seed is None else int(seed) + 1)
    return rng.random(n_rays)


def nyquist_window(dphi: np.ndarray) -> np.ndarray:
    """Taper for the PO samples: 1 below ``pi/2`` phase step, cos^2 roll-off to 0 at ``pi``."""
    x = np.clip((np.asarray(dphi) - 0.5 * math.pi) / (0.5 * math.pi), 0.0, 1.0)
    return np.where(x < 1.0, np.cos(0.5 * math.pi * x) ** 2, 0.0)  # exactly 0 beyond pi


def ray_angles(
    azimuth_fov_rad: float,
    elevation_fov_rad: float,
    spacing_rad: float,
    *,
    seed: int | None = None,
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Azimuth and elevation of every ray of :func:`ray_grid` (same grid, same jitter).

    Returns
    -------
    azimuth_rad, elevation_rad : (N,) float64 [rad].
    d_az, d_el : float — the grid's cell size [rad].
    """
    n_az = max(1, math.ceil(azimuth_fov_rad / spacing_rad - 1e-9))
    n_el = max(1, math.ceil(elevation_fov_rad / spacing_rad - 1e-9))
    d_az = azimuth_fov_rad / n_az
    d_el = elevation_fov_rad / n_el
    az = -0.5 * azimuth_fov_rad + (np.arange(n_az) + 0.5) * d_az
    el = -0.5 * elevation_fov_rad + (np.arange(n_el) + 0.5) * d_el
    az_g = np.repeat(az, n_el)
    el_g = np.tile(el, n_az)
    if seed is not None:
        rng = np.random.default_rng(seed)
        az_g = az_g + (rng.random(az_g.shape) - 0.5) * d_az
        el_g = el_g + (rng.random(el_g.shape) - 0.5) * d_el
    return az_g, el_g, d_az, d_el


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
    az_g, el_g, d_az, d_el = ray_angles(azimuth_fov_rad, elevation_fov_rad, spacing_rad,
                                        seed=seed)
    cos_el = np.cos(el_g)
    directions = np.stack([cos_el * np.cos(az_g), cos_el * np.sin(az_g), np.sin(el_g)], axis=1)
    solid_angle = cos_el * d_az * d_el
    return directions, solid_angle, math.sqrt(d_az * d_el)
