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
