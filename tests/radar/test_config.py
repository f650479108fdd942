"""RadarConfig: presets, derived values, validation messages."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from sim2radar.radar import RadarConfig, RadarConfigError, load_radar_config, preset_names


def test_presets_exist():
    assert {"ti-mmwcas", "ti-iwr1843"} <= set(preset_names())


def test_mmwcas_derived_values_match_the_paper():
    r = load_radar_config("ti-mmwcas")
    assert r.range_resolution_m == pytest.approx(0.038, abs=5e-4)  # c / 2B, B = 3.95 GHz
    assert r.n_virtual == 12 * 16
    assert r.n_azimuth_virtual == 86
    assert math.degrees(r.azimuth_resolution_rad) == pytest.approx(1.18, abs=0.01)
    assert r.azimuth_fov_deg == pytest.approx(120)
    # max range f_s c / (2 S) = N_adc * dR
    assert r.max_range_m == pytest.approx(r.adc_samples * r.range_resolution_m, rel=1e-9)
    assert r.wavelength_m == pytest.approx(3.8e-3, abs=1e-4)


def test_iwr1843_is_3tx_4rx():
    r = load_radar_config("ti-iwr1843")
    assert len(r.tx_antennas_half_wl) == 3 and len(r.rx_antennas_half_wl) == 4
    assert r.bandwidth_hz == pytest.approx(4e9)
    assert r.n_azimuth_virtual == 8


def test_to_dict_is_json_and_round_trips(tmp_path):
    r = load_radar_config("ti-mmwcas")
    d = r.to_dict()
    assert d["chirp_slope_hz_per_s"] == pytest.approx(r.slope_hz_per_s)
    path = tmp_path / "r.yaml"
    path.write_text(yaml.safe_dump(d))
    r2 = load_radar_config(path)
    assert r2.content_hash() == r.content_hash()
    assert r.with_updates(max_bounces=1).content_hash() != r.content_hash()


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("bandwidth_hz", -1e9),
        ("tx_antennas_half_wl", []),
        ("rx_antennas_half_wl", []),
        ("azimuth_fov_deg", 200.0),
        ("elevation_fov_deg", 0.0),
        ("adc_samples", 0),
        ("max_bounces", 0),
        ("ray_spacing_deg", -0.1),
    ],
)
def test_bad_values_name_the_field(tmp_path, field, value):
    doc = load_radar_config("ti-mmwcas").model_dump(mode="json")
    doc[field] = value
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(RadarConfigError) as info:
        load_radar_config(path)
    assert field in str(info.value) and str(path) in str(info.value)


def test_inconsistent_slope_is_explained():
    with pytest.raises(RadarConfigError, match="chirp_slope_hz_per_s"):
        load_radar_config("ti-mmwcas", chirp_slope_hz_per_s=1e12)


def test_unknown_field_rejected():
    with pytest.raises(RadarConfigError, match="bandwith_hz"):
        load_radar_config("ti-mmwcas", bandwith_hz=1e9)


def test_unknown_preset_lists_presets():
    with pytest.raises(RadarConfigError, match="ti-mmwcas"):
        load_radar_config("no-such-radar")


def test_unknown_material_in_scattering_rejected():
    with pytest.raises(RadarConfigError, match="unobtainium"):
        load_radar_config("ti-mmwcas", scattering={"coefficients": {"unobtainium": 0.3}})


def test_bins_are_uniform_in_sine_centred_on_boresight_and_cover_the_fov():
    """Beams of a virtual array have a constant width in u = sin(angle): the bins follow it,
    one centred on boresight, width = the array's resolution at boresight."""
    r = load_radar_config("ti-mmwcas")
    for u, width, fov in ((r.azimuth_bins_u, r.azimuth_bin_u, r.azimuth_fov_rad),
                          (r.elevation_bins_u, r.elevation_bin_u, r.elevation_fov_rad)):
        assert len(u) % 2 == 1 and u[len(u) // 2] == 0.0
        np.testing.assert_allclose(np.diff(u), width, rtol=1e-12)
        assert u[-1] + width / 2 >= math.sin(fov / 2) > u[-1] - width / 2
    assert r.azimuth_bin_u == pytest.approx(r.azimuth_resolution_rad)
    assert (r.n_azimuth_bins, r.n_elevation_bins) == (85, 3)
    np.testing.assert_allclose(r.azimuth_bins_rad, np.arcsin(r.azimuth_bins_u), atol=1e-7)
    # off boresight a bin spans width / cos(angle)
    k = r.n_azimuth_bins // 2 + 36
    span = np.arcsin(r.azimuth_bins_u[k] + r.azimuth_bin_u / 2) - np.arcsin(
        r.azimuth_bins_u[k] - r.azimuth_bin_u / 2)
    assert span == pytest.approx(r.azimuth_bin_u / math.cos(r.azimuth_bins_rad[k]), rel=0.01)
    assert RadarConfig.model_validate(r.to_dict()).n_rays == r.n_rays
    # a 180 deg field of view keeps every bin in visible space (|u| <= 1)
    wide = r.with_updates(azimuth_fov_deg=180.0)
    assert np.all(np.abs(wide.azimuth_bins_u) <= 1.0)


def test_noise_floor_is_derived_unless_typed():
    r = load_radar_config("ti-mmwcas")
    assert r.detection.noise_floor_db is None and r.detection.add_noise
    typed = load_radar_config("ti-mmwcas", detection={"noise_floor_db": -105.0})
    assert typed.detection.noise_floor_db == -105.0
    with pytest.raises(RadarConfigError, match="noise_floor_db"):
        load_radar_config("ti-mmwcas", detection={"noise_floor_db": float("nan")})


def test_scattering_model_fields_are_validated():
    r = load_radar_config("ti-mmwcas")
    assert r.scattering.model == "lambertian" and not r.scattering.transmission
    d = load_radar_config(
        "ti-mmwcas",
        scattering={"model": "directive", "lobe_exponent": {"Drywall": 5}, "lobe_default": 2.0,
                    "transmission": True, "slab_thickness_m": {"glass": 0.008}},
    )
    assert d.scattering.lobe("plasterboard") == 5.0  # alias resolved
    assert d.scattering.lobe("fabric") == 2.0  # not listed: the default
    assert d.scattering.transmits("glass") and not d.scattering.transmits("concrete")
    assert not r.scattering.transmits("glass")  # transmission off by default
    for bad, field in (
        ({"model": "phong"}, "model"),
        ({"lobe_exponent": {"unobtainium": 3.0}}, "unobtainium"),
        ({"lobe_exponent": {"glass": -1.0}}, "lobe_exponent"),
        ({"lobe_default": -2.0}, "lobe_default"),
        ({"transmission": "sometimes"}, "transmission"),
    ):
        with pytest.raises(RadarConfigError, match=field):
            load_radar_config("ti-mmwcas", scattering=bad)


def test_every_known_material_has_a_documented_lobe_default():
    from sim2radar.radar.config import DEFAULT_LOBE_EXPONENTS, DEFAULT_SCATTERING_COEFFICIENTS

    assert set(DEFAULT_LOBE_EXPONENTS) == set(DEFAULT_SCATTERING_COEFFICIENTS)
    assert all(0.0 <= a <= 1000.0 for a in DEFAULT_LOBE_EXPONENTS.values())
