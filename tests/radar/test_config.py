"""RadarConfig: presets, derived values, validation messages."""

from __future__ import annotations

import math

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


def test_bins_cover_the_fov():
    r = load_radar_config("ti-mmwcas")
    az = r.azimuth_bins_rad
    assert len(az) == r.n_azimuth_bins and az[0] > -r.azimuth_fov_rad / 2
    width = az[1] - az[0]
    assert width <= r.azimuth_resolution_rad + 1e-9
    assert RadarConfig.model_validate(r.to_dict()).n_rays == r.n_rays
