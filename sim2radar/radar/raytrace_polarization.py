"""Polarisation of the radar ray tracer: Jones-vector operations on Dr.Jit arrays.

With ``radar.hardware.polarization`` set (``prep.polarized`` in the tracer), a ray carries a
complex field vector ``(re, im)`` (two ``mi.Vector3f``) instead of a complex scalar: it starts as
the TX antenna's polarisation along the ray (:func:`antenna_polarization`), each reflection or
slab transmission sends it through the interface's TE/TM coefficients in the local Jones basis
(:func:`te_basis`, :func:`jones`, :func:`apply_interaction`), and the RX antenna's polarisation
dotted with the arriving field is what is received. Used by the bounce loop of
:mod:`sim2radar.radar.raytrace_bounces`.

Every function is vectorised over all rays; ``mi`` and ``dr`` are the ``mitsuba`` and ``drjit``
modules with the tracer's variant set (passed in, so that importing this module stays cheap).
"""

from __future__ import annotations

__all__ = ["antenna_polarization", "apply_interaction", "jones", "te_basis"]


def te_basis(mi, dr, k, n):
    """Unit TE vector ``s = k x n / |k x n|`` of a wave along ``k`` meeting a surface of
    normal ``n`` (Sionna RT's Jones basis; any vector normal to ``k`` at normal
    incidence)."""
    s = dr.cross(k, n)
    n2 = dr.squared_norm(s)
    alt = dr.cross(k, dr.select(dr.abs(k.z) < 0.9, mi.Vector3f(0.0, 0.0, 1.0),
                                mi.Vector3f(1.0, 0.0, 0.0)))
    s = dr.select(n2 > 1e-12, s, alt)
    return s * dr.rsqrt(dr.maximum(dr.squared_norm(s), 1e-30))


def jones(dr, field, s, k_in, k_out, te, tm):
    """A complex field vector ``field = (re, im)`` through one interaction: ``r_te (E.s) s +
    r_tm (E.p_in) p_out`` with ``p = k x s`` for the incoming and outgoing directions
    (reflection: ``k_out`` the reflected or returning direction; transmission through a
    slab: ``k_out = k_in``); ``te``, ``tm`` = (re, im) coefficients (ITU-R P.2040-3
    eq. (31) / (43); Sionna RT's sign convention, ``r_tm = -r_te`` at normal incidence).
    """
    e_re, e_im = field
    p_in, p_out = dr.cross(k_in, s), dr.cross(k_out, s)
    es_re, es_im = dr.dot(e_re, s), dr.dot(e_im, s)
    ep_re, ep_im = dr.dot(e_re, p_in), dr.dot(e_im, p_in)
    a_re = te[0] * es_re - te[1] * es_im
    a_im = te[0] * es_im + te[1] * es_re
    b_re = tm[0] * ep_re - tm[1] * ep_im
    b_im = tm[0] * ep_im + tm[1] * ep_re
    return a_re * s + b_re * p_out, a_im * s + b_im * p_out


def apply_interaction(dr, carry, op):
    """``carry`` through one interaction ``op``: ``("scalar", (re, im), None)`` multiplies a
    complex scalar carry; ``("jones", (s, k_in, k_out, te, tm), scale)`` sends a field
    vector through :func:`jones` and multiplies it by the real ``scale`` (if any)."""
    kind, args, scale = op
    if kind == "scalar":
        return (carry[0] * args[0] - carry[1] * args[1],
                carry[0] * args[1] + carry[1] * args[0])
    out = jones(dr, carry, *args)
    return out if scale is None else (out[0] * scale, out[1] * scale)


def antenna_polarization(dr, d, up, slant: tuple[float, float]):
    """The antennas' unit polarisation vector for the direction ``d`` [world] (a wave
    leaving the TX along ``d``, or reaching the RX from ``d``): ``cos(slant) v + sin(slant)
    h`` with ``v`` the radar's up axis ``up`` made normal to ``d`` (theta-hat up to sign,
    Sionna RT's "V") and ``h = up x d`` normalised (phi-hat, "H"). ``slant`` is
    ``(cos, sin)`` of the antennas' slant from vertical (``Prepared.slant``)."""
    c, s = slant
    v = up - dr.dot(up, d) * d
    e = v * (c * dr.rsqrt(dr.maximum(dr.squared_norm(v), 1e-30)))
    if s != 0.0:
        h = dr.cross(up, d)
        e = e + h * (s * dr.rsqrt(dr.maximum(dr.squared_norm(h), 1e-30)))
    return e
