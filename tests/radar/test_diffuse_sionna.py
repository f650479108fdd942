"""Diffuse scattering against an independent solver: Sionna RT's monostatic diffuse backscatter
of a flat plate (fixture ``fixtures/sionna_diffuse.json``, made by
``scripts/sionna_diffuse_fixture.py`` with sionna-rt 2.2.0; sionna-rt is not a test
dependency).

Case: a 2 m x 2 m plate (one quad) whose centre lies 3 m from the radar, seen at 0, 20, 40 and
60 degrees incidence; concrete (S = 0.5, directive alpha_R = 3) and wood (S = 0.35, alpha_R =
6), Lambertian and directive patterns; one bounce, diffuse only. The fixture's ``unpolarised``
entries are the mean of Sionna's V and H powers, which equals the same model with the
unpolarised Fresnel power ``(|r_TE|^2 + |r_TM|^2) / 2`` — the tracer's unpolarised mode
(sim2radar/radar/returns.py, item 2: ``|a_d|^2 = S^2 |Gamma|^2 dOmega f_s / r_o^2`` summed over
the rays), in the project's normalisation (``|a|^2 = Sionna's |a|^2 (4 pi / lambda)^2``).

The tracer is run with S = 1 for the plate's material (its physical-optics term is then
``sqrt(1 - S^2) = 0``: diffuse only) and its power scaled by the fixture's S^2 (the diffuse
power is proportional to S^2). The sums differ only by the ray grids (Sionna: a Fibonacci
sphere of 4 million rays; ours: the preset's az/el grid at 0.1 deg), so 1 dB (the issue's
tolerance) is a loose bound; the test asserts 0.1 dB.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sim2radar.mesh import MaterialMesh
from sim2radar.radar import RadarScene

FIXTURE = json.loads((Path(__file__).parent / "fixtures" / "sionna_diffuse.json").read_text())
TOLERANCE_DB = 0.1  # measured: within 0.015 dB in all 16 cases


def _plate(material: str, incidence_deg: float) -> MaterialMesh:
    """The fixture's plate: 2 x 2 m, centre (3, 0, 0), normal towards the radar turned by the
    incidence angle about the vertical axis through the centre (one quad)."""
    (w, h), c = FIXTURE["plate"]["size_m"], np.array(FIXTURE["plate"]["centre_m"])
    a = math.radians(incidence_deg)
    along = np.array([math.sin(a), math.cos(a), 0.0])   # the plate's horizontal axis
    up = np.array([0.0, 0.0, 1.0])
    v = np.array([c + sa * w / 2 * along + sz * h / 2 * up
                  for sa, sz in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return MaterialMesh(v, np.array([[0, 1, 2], [0, 2, 3]]), material, name="plate")


def test_fixture_is_the_model_it_claims():
    assert FIXTURE["frequency_hz"] == pytest.approx(78.975e9)
    assert len(FIXTURE["unpolarised"]) == 16
    for case in FIXTURE["cases"]:
        assert case["xpd_coefficient"] == 0.0 and case["convergence_max_abs_db"] < 0.05


@pytest.mark.parametrize("entry", FIXTURE["unpolarised"],
                         ids=lambda e: f"{e['material']}-{e['pattern']}-{e['incidence_deg']:g}")
def test_diffuse_backscatter_of_a_plate_matches_sionna_rt(mmwcas, entry):
    material, pattern = entry["material"], entry["pattern"]
    case = next(c for c in FIXTURE["cases"] if c["material"] == material)
    s = case["scattering_coefficient"]
    radar = mmwcas.with_updates(
        azimuth_fov_deg=60.0, elevation_fov_deg=50.0, ray_spacing_deg=0.1, max_bounces=1,
        scattering={"model": pattern, "coefficients": {material: 1.0},
                    "lobe_exponent": {material: float(entry.get("alpha_r") or 0.0)}})
    assert radar.center_frequency_hz == pytest.approx(FIXTURE["frequency_hz"])
    paths = RadarScene([_plate(material, entry["incidence_deg"])]).trace_paths(
        radar, prune_below_noise_db=None)
    power = s**2 * float(np.sum(np.abs(paths.amplitude) ** 2))
    ours_db = 10 * math.log10(power)
    assert ours_db == pytest.approx(entry["power_project_db"], abs=TOLERANCE_DB), (
        f"ours {ours_db:.2f} dB, Sionna RT {entry['power_project_db']:.2f} dB")
