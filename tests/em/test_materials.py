"""ITU-R P.2040-3 material table: values, name handling, frequency-range warnings."""

from __future__ import annotations

import math
import warnings

import pytest

from sim2radar import em
from sim2radar.constants import VACUUM_PERMITTIVITY_F_M
from sim2radar.vocab import MATERIAL_CLASSES

ITU_ROWS = [
    "concrete",
    "brick",
    "plasterboard",
    "wood",
    "glass",
    "ceiling_board",
    "chipboard",
    "plywood",
    "marble",
    "floorboard",
    "metal",
    "vinyl_tile",
    "carpet_tile",
]


def test_concrete_at_77_ghz_matches_itu_table():
    # ITU-R P.2040-3 Table 3: eps' = 5.24 f^0, sigma = 0.0462 f^0.7822 (f in GHz)
    eps_r, sigma = em.material_parameters("concrete", 77e9)
    assert eps_r == pytest.approx(5.24)
    assert sigma == pytest.approx(0.0462 * 77**0.7822, rel=1e-12)
    assert sigma == pytest.approx(1.38, abs=0.01)


def test_complex_permittivity_imaginary_part_is_sigma_over_omega_eps0():
    eta = em.complex_permittivity("concrete", 77e9)
    sigma = 0.0462 * 77**0.7822
    assert eta.real == pytest.approx(5.24)
    assert eta.imag == pytest.approx(-sigma / (2 * math.pi * 77e9 * VACUUM_PERMITTIVITY_F_M))
    # ITU-R P.2040-3 eq. (9b) shorthand: eps'' = 17.98 sigma / f_GHz
    assert -eta.imag == pytest.approx(17.98 * sigma / 77, rel=1e-3)


@pytest.mark.parametrize("name", list(MATERIAL_CLASSES) + ITU_ROWS)
def test_every_vlm_class_and_itu_row_resolves(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", em.MaterialFrequencyWarning)
        eta = em.complex_permittivity(name, 77e9)
    assert eta.real >= 1.0 and eta.imag <= 0.0
    assert em.get_material(name).source


def test_names_are_normalised_and_aliased():
    assert em.complex_permittivity("Ceiling board", 77e9) == em.complex_permittivity(
        "ceiling_board", 77e9
    )
    assert em.get_material("Ceramic-Tile").name == "ceramic_tile"
    assert "metal" in em.material_names() and "unknown" in em.material_names()


def test_unknown_material_lists_known_names():
    with pytest.raises(KeyError) as info:
        em.complex_permittivity("unobtainium", 77e9)
    msg = str(info.value)
    assert "unobtainium" in msg and "concrete" in msg and "metal" in msg


def test_out_of_range_extrapolates_with_one_warning_per_material():
    em.materials._WARNED.clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        a = em.complex_permittivity("brick", 77e9)  # brick row: 1-40 GHz
        b = em.complex_permittivity("brick", 78e9)
    brick = [w for w in caught if issubclass(w.category, em.MaterialFrequencyWarning)]
    assert len(brick) == 1 and "brick" in str(brick[0].message)
    # extrapolated with the same power law
    assert a.real == pytest.approx(3.91)
    assert -a.imag * 77 == pytest.approx(-b.imag * 78 * (77 / 78) ** 0.16, rel=1e-9)


def test_in_range_does_not_warn():
    em.materials._WARNED.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("error", em.MaterialFrequencyWarning)
        em.complex_permittivity("glass", 77e9)
        em.complex_permittivity("glass", 300e9)  # second (220-450 GHz) row


def test_glass_uses_the_row_for_the_frequency():
    assert em.material_parameters("glass", 77e9)[0] == pytest.approx(6.31)
    assert em.material_parameters("glass", 300e9)[0] == pytest.approx(5.79)


def test_bad_frequency_is_rejected():
    with pytest.raises(ValueError, match="frequency_hz"):
        em.complex_permittivity("wood", -1.0)
