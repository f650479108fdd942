"""Fresnel half-space and single-layer slab reflection (ITU-R P.2040-3)."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar import em
from sim2radar.constants import SPEED_OF_LIGHT_M_S

F = 77e9


@pytest.mark.parametrize("material", ["concrete", "glass", "wood", "plasterboard", "fabric"])
def test_normal_incidence_matches_closed_form(material):
    eta = em.complex_permittivity(material, F)
    expected = abs((1 - np.sqrt(eta)) / (1 + np.sqrt(eta)))
    r_te, r_tm = em.reflection_coefficients(material, F, 0.0)
    assert abs(r_te) == pytest.approx(expected, rel=1e-12)
    assert abs(r_tm) == pytest.approx(expected, rel=1e-12)
    assert r_tm == pytest.approx(-r_te)  # ITU sign convention


def test_metal_reflects_almost_everything():
    # up to 80 deg: closer to grazing even metal shows a (pseudo-Brewster) TM dip
    theta = np.linspace(0, np.radians(80), 50)
    r_te, r_tm = em.reflection_coefficients("metal", F, theta)
    assert np.all(np.abs(r_te) > 0.99) and np.all(np.abs(r_tm) > 0.99)


def test_glass_tm_dips_at_brewster_angle():
    eps_r = em.material_parameters("glass", F)[0]
    brewster = np.arctan(np.sqrt(eps_r))
    theta = np.linspace(0, np.pi / 2 - 1e-3, 4001)
    _, r_tm = em.reflection_coefficients("glass", F, theta)
    dip = theta[np.argmin(np.abs(r_tm))]
    assert dip == pytest.approx(brewster, abs=np.radians(1.0))
    assert np.abs(r_tm).min() < 0.05  # near-zero for low-loss glass
    r_te, _ = em.reflection_coefficients("glass", F, brewster)
    assert abs(r_te) > 0.5  # TE does not dip


def test_grazing_incidence_reflects_fully():
    r_te, r_tm = em.reflection_coefficients("concrete", F, np.pi / 2)
    assert abs(r_te) == pytest.approx(1.0, abs=1e-9) and abs(r_tm) == pytest.approx(1.0, abs=1e-9)


def test_slab_vanishes_for_zero_thickness():
    r_te, r_tm = em.reflection_coefficients("glass", F, 0.3, thickness_m=0.0)
    assert abs(r_te) < 1e-12 and abs(r_tm) < 1e-12
    r_te, _ = em.reflection_coefficients("glass", F, 0.3, thickness_m=1e-6)
    assert abs(r_te) < 0.01


def test_lossless_slab_is_periodic_in_thickness():
    eta = 4.0 + 0j
    theta = 0.4
    lam = SPEED_OF_LIGHT_M_S / F
    period = lam / (2 * np.sqrt(eta.real - np.sin(theta) ** 2))
    d = np.linspace(0.0005, 0.003, 7)
    a = em.slab_coefficients(eta, theta, d, F)
    b = em.slab_coefficients(eta, theta, d + period, F)
    np.testing.assert_allclose(a[0], b[0], atol=1e-9)
    np.testing.assert_allclose(a[1], b[1], atol=1e-9)
    # half a period (quarter-wave layer pair) gives the maximum, a full one zero
    assert np.abs(em.slab_coefficients(eta, theta, period, F)[0]) < 1e-9


def test_thick_lossy_slab_tends_to_half_space():
    r_half, _ = em.reflection_coefficients("concrete", F, 0.2)
    r_slab, _ = em.reflection_coefficients("concrete", F, 0.2, thickness_m=0.5)
    assert abs(r_slab) == pytest.approx(abs(r_half), rel=1e-3)


def test_unpolarised_power_is_mean_of_te_tm():
    theta = np.linspace(0, 1.4, 9)
    r_te, r_tm = em.reflection_coefficients("wood", F, theta)
    r = em.unpolarized_reflection("wood", F, theta)
    np.testing.assert_allclose(np.abs(r) ** 2, 0.5 * (np.abs(r_te) ** 2 + np.abs(r_tm) ** 2))
    assert abs(em.unpolarized_reflection("metal", F, 0.0)) > 0.99


def test_bad_angle_rejected():
    with pytest.raises(ValueError, match="incidence_rad"):
        em.reflection_coefficients("wood", F, 2.0)


# --- slab transmission (ITU-R P.2040-3 §3, eq. (43b)) -------------------------------------


def test_lossless_slab_conserves_power_per_polarisation():
    """No absorption: every TE and TM wave is either reflected or transmitted."""
    eta = 4.0 + 0j
    theta = np.linspace(0.0, 1.5, 31)[:, None]
    d = np.array([0.0003, 0.001, 0.0037, 0.012])[None, :]
    r_te, r_tm = em.slab_coefficients(eta, theta, d, F)
    t_te, t_tm = em.slab_transmission_coefficients(eta, theta, d, F)
    np.testing.assert_allclose(np.abs(r_te) ** 2 + np.abs(t_te) ** 2, 1.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(r_tm) ** 2 + np.abs(t_tm) ** 2, 1.0, atol=1e-12)


def test_unpolarised_slab_coefficients_conserve_power_when_lossless(monkeypatch):
    """The unpolarised |R|^2 and |T|^2 are TE/TM means, so they conserve power too."""
    import sim2radar.em.fresnel as fresnel

    monkeypatch.setattr(fresnel, "complex_permittivity", lambda name, f: 2.73 + 0j)
    theta = np.linspace(0.0, 1.4, 15)
    r = fresnel.unpolarized_reflection("plasterboard", F, theta, 0.0125)
    t = fresnel.unpolarized_transmission("plasterboard", F, theta, 0.0125)
    np.testing.assert_allclose(np.abs(r) ** 2 + np.abs(t) ** 2, 1.0, atol=1e-12)


def test_slab_transmission_tends_to_one_for_zero_thickness():
    t_te, t_tm = em.transmission_coefficients("glass", F, 0.3, thickness_m=0.0)
    assert t_te == pytest.approx(1.0, abs=1e-12) and t_tm == pytest.approx(1.0, abs=1e-12)
    t = em.unpolarized_transmission("glass", F, np.array([0.0, 0.5, 1.0]), thickness_m=1e-6)
    np.testing.assert_allclose(np.abs(t), 1.0, atol=1e-3)


def test_lossy_slab_absorbs_power_and_more_when_thicker():
    """Plasterboard and concrete are lossy at 77 GHz (Im eta < 0): R + T < 1, falling with d."""
    theta = np.array([0.0, 0.4, 0.8])
    for material in ("plasterboard", "concrete"):
        lost = []
        for d in (0.005, 0.0125, 0.05):
            r = em.unpolarized_reflection(material, F, theta, d)
            t = em.unpolarized_transmission(material, F, theta, d)
            balance = np.abs(r) ** 2 + np.abs(t) ** 2
            assert np.all(balance < 1.0 - 1e-4), (material, d, balance)
            lost.append(1.0 - balance)
        assert np.all(lost[0] < lost[2])
    # one-way absorption ~ exp(-2 k |Im sqrt(eta)| d): 12.5 mm plasterboard passes ~ -7 dB
    # at normal incidence (k = 1.6e3 rad/m, Im sqrt(eta) = -0.036), 0.2 m concrete nothing
    t_pb = em.unpolarized_transmission("plasterboard", F, 0.0, 0.0125)
    t_cc = em.unpolarized_transmission("concrete", F, 0.0, 0.2)
    assert 0.1 < abs(t_pb) ** 2 < 0.4 and abs(t_cc) ** 2 < 1e-4


def test_metal_slab_transmits_nothing():
    t = em.unpolarized_transmission("metal", F, np.array([0.0, 0.7]), 0.001)
    assert np.all(np.abs(t) < 1e-6)


def test_transmission_phase_is_the_delay_across_the_slab_for_a_matched_slab():
    """A slab with eta = 1 is free space: T = e^{-j k d cos t}, R = 0."""
    lam = SPEED_OF_LIGHT_M_S / F
    theta, d = 0.5, 0.01
    t_te, _ = em.slab_transmission_coefficients(1.0 + 0j, theta, d, F)
    assert t_te == pytest.approx(np.exp(-2j * np.pi * d / lam * np.cos(theta)), abs=1e-12)
