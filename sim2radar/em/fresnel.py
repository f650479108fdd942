"""Fresnel reflection at a half-space; reflection and transmission of a single-layer slab
(ITU-R P.2040-3).

Conventions
-----------
* Time dependence e^{+j omega t}; lossy media have ``Im(eta) < 0``.
* ``incidence_rad`` is measured from the surface normal (0 = normal incidence,
  pi/2 = grazing).
* TE = electric field perpendicular to the plane of incidence ("s"), TM = parallel ("p").
* Sign convention of the TM coefficient as in ITU-R P.2040-3 (and Sionna RT): at normal
  incidence ``r_tm = -r_te``.

Equations
---------
Half-space, incident from vacuum (ITU-R P.2040-3 §2.2, eq. (31))::

    r_te = (cos t - sqrt(eta - sin^2 t)) / (cos t + sqrt(eta - sin^2 t))
    r_tm = (eta cos t - sqrt(eta - sin^2 t)) / (eta cos t + sqrt(eta - sin^2 t))

Single-layer slab of thickness ``d`` in vacuum (ITU-R P.2040-3 §3, multiple internal
reflections summed; eqs. (43a), (43b) and (44) in the numbering that Sionna RT's
``itu_coefficients_single_layer_slab`` cites)::

    q = (2 pi d / lambda) sqrt(eta - sin^2 t)               eq. (44), electrical thickness
    R = r (1 - e^{-j 2 q}) / (1 - r^2 e^{-j 2 q})           eq. (43a), r = r_te or r_tm above
    T = (1 - r^2) e^{-j q} / (1 - r^2 e^{-j 2 q})           eq. (43b)

``R -> 0`` and ``T -> 1`` as ``d -> 0``; for a lossless slab ``|R|^2 + |T|^2 = 1`` and ``R`` is
periodic in ``d`` with period ``lambda / (2 sqrt(eta - sin^2 t))``; a lossy slab absorbs
``1 - |R|^2 - |T|^2 > 0``. ``T`` is the field leaving the back face relative to the field
arriving at the front face (the wave leaves the slab parallel to the incident direction, as
both sides are vacuum); its phase ``-q`` is the phase delay across the slab along the normal.
"""

from __future__ import annotations

import numpy as np

from sim2radar.constants import SPEED_OF_LIGHT_M_S
from sim2radar.em.materials import complex_permittivity

__all__ = [
    "fresnel_coefficients",
    "slab_coefficients",
    "slab_transmission_coefficients",
    "reflection_coefficients",
    "transmission_coefficients",
    "unpolarized_reflection",
    "unpolarized_transmission",
]


def _csqrt(z: np.ndarray) -> np.ndarray:
    """Principal complex square root with ``Im >= 0`` flipped to the decaying branch.

    For e^{+j omega t}, a wave decaying into the medium needs ``Im(sqrt(.)) <= 0``; NumPy's
    principal root of ``eta - sin^2`` (``Im(eta) <= 0``) already has ``Im <= 0``.
    """
    return np.sqrt(z.astype(np.complex128))


def fresnel_coefficients(
    eta: complex | np.ndarray, incidence_rad: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Half-space Fresnel amplitude reflection coefficients (ITU-R P.2040-3, eq. (31)).

    Parameters
    ----------
    eta : complex or array
        Complex relative permittivity of the half-space [-] (broadcast with the angle).
    incidence_rad : float or array
        Angle of incidence from the normal [rad], in [0, pi/2].

    Returns
    -------
    r_te, r_tm : complex128 arrays (broadcast shape) [-]
    """
    theta = np.asarray(incidence_rad, dtype=np.float64)
    if np.any(~np.isfinite(theta)) or np.any(theta < 0) or np.any(theta > np.pi / 2 + 1e-9):
        raise ValueError("incidence_rad must lie in [0, pi/2] (measured from the normal)")
    eta = np.asarray(eta, dtype=np.complex128)
    cos_t = np.cos(theta)
    sin2 = np.sin(theta) ** 2
    root = _csqrt(eta - sin2)
    r_te = (cos_t - root) / (cos_t + root)  # ITU-R P.2040-3, eq. (31a)
    r_tm = (eta * cos_t - root) / (eta * cos_t + root)  # ITU-R P.2040-3, eq. (31b)
    return r_te, r_tm


def _slab_terms(
    eta: complex | np.ndarray,
    incidence_rad: float | np.ndarray,
    thickness_m: float | np.ndarray,
    frequency_hz: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Half-space ``r_te``, ``r_tm`` and the slab phase factor ``e^{-j q}`` (eq. (44))."""
    d = np.asarray(thickness_m, dtype=np.float64)
    if np.any(~np.isfinite(d)) or np.any(d < 0):
        raise ValueError("thickness_m must be finite and >= 0")
    r_te, r_tm = fresnel_coefficients(eta, incidence_rad)
    wavelength_m = SPEED_OF_LIGHT_M_S / float(frequency_hz)
    theta = np.asarray(incidence_rad, dtype=np.float64)
    q = 2.0 * np.pi * d / wavelength_m * _csqrt(np.asarray(eta) - np.sin(theta) ** 2)  # (44)
    return r_te, r_tm, np.exp(-1j * q)


def slab_coefficients(
    eta: complex | np.ndarray,
    incidence_rad: float | np.ndarray,
    thickness_m: float | np.ndarray,
    frequency_hz: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Reflection coefficients of a single homogeneous slab in vacuum (ITU-R P.2040-3 §3).

    Parameters
    ----------
    eta : complex or array
        Complex relative permittivity of the slab [-].
    incidence_rad : float or array
        Angle of incidence from the normal [rad].
    thickness_m : float or array
        Slab thickness [m], >= 0.
    frequency_hz : float
        Frequency [Hz].

    Returns
    -------
    r_te, r_tm : complex128 arrays [-]
    """
    r_te, r_tm, phase_q = _slab_terms(eta, incidence_rad, thickness_m, frequency_hz)
    phase = phase_q**2  # e^{-j 2 q}
    out = []
    for r in (r_te, r_tm):
        out.append(r * (1.0 - phase) / (1.0 - r**2 * phase))  # ITU-R P.2040-3, eq. (43a)
    return out[0], out[1]


def slab_transmission_coefficients(
    eta: complex | np.ndarray,
    incidence_rad: float | np.ndarray,
    thickness_m: float | np.ndarray,
    frequency_hz: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Transmission coefficients of a single homogeneous slab in vacuum (ITU-R P.2040-3 §3).

    ``T = (1 - r^2) e^{-j q} / (1 - r^2 e^{-j 2 q})`` (eq. (43b)): the multiply reflected
    waves inside the slab summed; ``T = 1`` at ``d = 0``.

    Parameters
    ----------
    eta : complex or array
        Complex relative permittivity of the slab [-].
    incidence_rad : float or array
        Angle of incidence from the normal [rad], in [0, pi/2].
    thickness_m : float or array
        Slab thickness [m], >= 0.
    frequency_hz : float
        Frequency [Hz].

    Returns
    -------
    t_te, t_tm : complex128 arrays [-] (field behind the slab / field incident on it)
    """
    r_te, r_tm, phase_q = _slab_terms(eta, incidence_rad, thickness_m, frequency_hz)
    out = []
    for r in (r_te, r_tm):
        r2 = r**2
        out.append((1.0 - r2) * phase_q / (1.0 - r2 * phase_q**2))  # ITU-R P.2040-3, eq. (43b)
    return out[0], out[1]


def reflection_coefficients(
    material: str,
    frequency_hz: float,
    incidence_rad: float | np.ndarray,
    thickness_m: float | np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Fresnel TE/TM amplitude reflection coefficients of a named material.

    Parameters
    ----------
    material : str
        Material name (see :func:`sim2radar.em.material_names`).
    frequency_hz : float
        Frequency [Hz].
    incidence_rad : float or array
        Angle of incidence from the normal [rad], in [0, pi/2].
    thickness_m : float or array, optional
        If given, the single-layer slab model (ITU-R P.2040-3 §3) of that thickness [m];
        otherwise a half-space (eq. (31)).

    Returns
    -------
    r_te, r_tm : complex128 (scalars as 0-d arrays, else the broadcast shape) [-]
    """
    eta = complex_permittivity(material, frequency_hz)
    if thickness_m is None:
        return fresnel_coefficients(eta, incidence_rad)
    return slab_coefficients(eta, incidence_rad, thickness_m, frequency_hz)


def unpolarized_reflection(
    material: str,
    frequency_hz: float,
    incidence_rad: float | np.ndarray,
    thickness_m: float | np.ndarray | None = None,
) -> np.ndarray:
    """Reflection coefficient for an unpolarised (or polarisation-agnostic) wave.

    Magnitude from the mean reflected power, phase from the TE coefficient::

        |R| = sqrt((|r_te|^2 + |r_tm|^2) / 2),   arg R = arg r_te

    (the complex mean of ``r_te`` and ``r_tm`` would wrongly vanish at normal incidence,
    where ``r_tm = -r_te`` in the ITU sign convention).

    Returns
    -------
    complex128 array [-]
    """
    r_te, r_tm = reflection_coefficients(material, frequency_hz, incidence_rad, thickness_m)
    mag = np.sqrt(0.5 * (np.abs(r_te) ** 2 + np.abs(r_tm) ** 2))
    return mag * np.exp(1j * np.angle(r_te))


def transmission_coefficients(
    material: str,
    frequency_hz: float,
    incidence_rad: float | np.ndarray,
    thickness_m: float | np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """TE/TM amplitude transmission coefficients of a slab of a named material
    (ITU-R P.2040-3 §3, eq. (43b)); a half-space transmits nothing back into vacuum, so the
    thickness [m] is required.

    Returns
    -------
    t_te, t_tm : complex128 [-]
    """
    eta = complex_permittivity(material, frequency_hz)
    return slab_transmission_coefficients(eta, incidence_rad, thickness_m, frequency_hz)


def unpolarized_transmission(
    material: str,
    frequency_hz: float,
    incidence_rad: float | np.ndarray,
    thickness_m: float | np.ndarray,
) -> np.ndarray:
    """Slab transmission coefficient for an unpolarised wave, built like
    :func:`unpolarized_reflection`: ``|T| = sqrt((|t_te|^2 + |t_tm|^2) / 2)``, phase of ``t_te``.

    With :func:`unpolarized_reflection` of the same slab, ``|R|^2 + |T|^2 = 1`` for a lossless
    material (both are the means of the TE and TM powers, each of which is conserved).

    Returns
    -------
    complex128 array [-]
    """
    t_te, t_tm = transmission_coefficients(material, frequency_hz, incidence_rad, thickness_m)
    mag = np.sqrt(0.5 * (np.abs(t_te) ** 2 + np.abs(t_tm) ** 2))
    return mag * np.exp(1j * np.angle(t_te))
