"""Artefact figures of a radar dataset (`sim2radar/evaluate/artefacts.py`).

Frames with known answers: strong targets with arcs of points 20 dB weaker at their range
(what a beamformer's angle sidelobes leave), and points scattered uniformly (no sidelobes, only
chance neighbours). The report-level checks (``gap.json["artefacts"]``) are in test_gap.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.datasets import Frame, write_dataset, write_metadata
from sim2radar.evaluate.artefacts import (
    DEFAULT_RESOLUTION_FROM,
    UNDECLARED,
    ArtefactSettings,
    DatasetInfo,
    artefact_stats,
    doppler_edges,
    range_bins,
    read_dataset_info,
    sidelobe_flags,
    sidelobe_share,
)

RES_M = 0.038  # ArtefactSettings' default range resolution [m]
ARC_OFFSETS_DEG = np.concatenate([-np.arange(5.0, 51.0, 5.0), np.arange(5.0, 51.0, 5.0)])


def point_at(r_m, az_deg, db, z_m=0.0) -> list[float]:
    """One point at range r_m [m] in the horizontal plane (z_m = 0), azimuth az_deg [deg]."""
    a = np.radians(az_deg)
    horiz = np.sqrt(r_m ** 2 - z_m ** 2)
    return [horiz * np.cos(a), horiz * np.sin(a), z_m, db]


def arc_frame(rng) -> np.ndarray:
    """75 points: 3 strong targets (40 dB) at 3, 5 and 7 m, each with an arc of 20 points 20 dB
    weaker at its range, 5°-50° either side of it (60 sidelobe points); at the first target's
    range also a point 2° from it (inside its main lobe) and one 30° away but only 10 dB weaker
    (neither is a sidelobe by the 3° / 13 dB rules); and 10 points of 20 dB clutter at 9 m."""
    pts = []
    for r, az0 in zip((3.0, 5.0, 7.0), rng.uniform(-30.0, 30.0, 3), strict=True):
        pts.append(point_at(r, az0, 40.0))
        pts += [point_at(r, az0 + d, 20.0) for d in ARC_OFFSETS_DEG]
        if r == 3.0:
            pts += [point_at(r, az0 + 2.0, 20.0), point_at(r, az0 - 30.0, 30.0)]
    pts += [point_at(9.0, az, 20.0) for az in np.linspace(-40.0, 40.0, 10)]
    return np.asarray(pts, np.float32)


def uniform_frame(rng, n: int = 300) -> np.ndarray:
    """n points uniform in range 1-10 m and azimuth ±60°, intensities uniform 0-40 dB."""
    r, az = rng.uniform(1.0, 10.0, n), np.radians(rng.uniform(-60.0, 60.0, n))
    return np.column_stack([r * np.cos(az), r * np.sin(az), rng.uniform(-0.5, 0.5, n),
                            rng.uniform(0.0, 40.0, n)]).astype(np.float32)


def _brute_force_flags(points, res_m, s: ArtefactSettings):
    """NumPy reference twin of sidelobe_flags: every pair, O(N²) broadcasting."""
    p = np.asarray(points, np.float64)
    b = np.floor(np.linalg.norm(p[:, :3], axis=1) / res_m + 0.5).astype(int)
    az = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
    d_bin = b[None, :] - b[:, None]                         # [i, j] = bin_j - bin_i
    sep = np.abs((az[None, :] - az[:, None] + 180.0) % 360.0 - 180.0)
    stronger = (p[None, :, 3] - p[:, None, 3] >= s.sidelobe_min_drop_db) \
        & (sep > s.sidelobe_min_separation_deg)
    tol, off = s.sidelobe_range_tolerance_bins, s.sidelobe_control_offset_bins
    return ((stronger & (np.abs(d_bin) <= tol)).any(1),
            (stronger & (np.abs(d_bin - off) <= tol)).any(1),
            (stronger & (np.abs(d_bin + off) <= tol)).any(1))


def test_sidelobe_flags_match_the_all_pairs_reference_in_any_chunking():
    rng = np.random.default_rng(10)
    s = ArtefactSettings()
    # ranges on 12 bins only: crowded windows, many pairs, ties in intensity at 13 dB
    n = 400
    r = (rng.integers(60, 72, n) + rng.uniform(-0.4, 0.4, n)) * RES_M
    az = np.radians(rng.uniform(-180.0, 180.0, n))
    pts = np.column_stack([r * np.cos(az), r * np.sin(az), np.zeros(n),
                           rng.integers(0, 5, n) * 6.5])           # 0, 6.5, ..., 26 dB
    want = _brute_force_flags(pts, RES_M, s)
    for max_pairs in (1, 97, 4_000_000):
        got = sidelobe_flags(pts, RES_M, s, max_pairs=max_pairs)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)
    assert 0 < want[0].sum() < n and want[1].sum() > 0 and want[2].sum() > 0


def test_sidelobe_flags_follow_the_bin_drop_and_angle_rules():
    res = 0.05
    bins = np.array([80, 81, 82, 83, 84, 85, 86, 87, 75, 80, 80, 80, 80])
    az = np.array([0.0, 30, 30, 30, 30, 30, 30, 30, 30, 2.5, 3.5, 30, -90])
    db = np.array([40.0, 20, 20, 20, 20, 20, 20, 20, 20, 20, 20, 27.5, 27])
    pts = np.array([point_at(b * res, a, d) for b, a, d in zip(bins, az, db, strict=True)])
    assert np.array_equal(range_bins(pts, res), bins)
    side, plus, minus = sidelobe_flags(pts, res)
    # +1 bin -> sidelobe; +4..+6 -> control (the stronger one 5 bins *below*: "minus" window);
    # -5 -> "plus"; +2, +3, +7 -> neither; within 3° -> no; 12.5 dB weaker -> no; 13 dB -> yes
    assert np.flatnonzero(side).tolist() == [1, 10, 12]
    assert np.flatnonzero(minus).tolist() == [4, 5, 6]
    assert np.flatnonzero(plus).tolist() == [8]
    # azimuth wraps: 179° and -179° are 2° apart (main lobe), 179° and -170° 11°
    wrap = np.array([point_at(4.0, 179.0, 40.0), point_at(4.0, -179.0, 20.0),
                     point_at(4.0, -170.0, 20.0)])
    assert sidelobe_flags(wrap, res)[0].tolist() == [False, False, True]


def test_sidelobe_arcs_read_far_above_their_control():
    rng = np.random.default_rng(11)
    frames = {f"f{i}": arc_frame(rng) for i in range(8)}
    sh = sidelobe_share(frames, RES_M)
    assert (sh.points, sh.on_sidelobe) == (8 * 75, 8 * 60)
    assert sh.share == pytest.approx(60 / 75) and sh.control_share == 0.0
    assert sh.difference == pytest.approx(0.8)
    art = artefact_stats(frames)
    assert art.beyond_range_share == pytest.approx(10 / 75)          # the clutter at 9 m
    assert art.sidelobe == sh and art.range_resolution_from == DEFAULT_RESOLUTION_FROM
    assert DEFAULT_RESOLUTION_FROM == "GapSettings default"           # the value gap.json carries


def test_uniformly_scattered_points_read_their_control():
    rng = np.random.default_rng(12)
    sh = sidelobe_share([uniform_frame(rng) for _ in range(30)], RES_M)
    assert sh.share > 0.1                                     # chance neighbours do happen
    assert abs(sh.difference) < 0.03                          # ... as often as 5 bins away
    # a control window twice as wide (either offset) would read well above the share
    assert sh.on_control_either / sh.points > sh.share + 0.05


def test_doppler_edges_stay_centred_on_zero_under_the_bin_cap():
    # bins stay centred on 0 when widened to respect the cap
    wide = doppler_edges([np.array([-30.0, 0.0, 30.0])], 0.1, max_bins=200)
    assert len(wide) - 1 <= 200 and np.any(np.isclose(wide, -np.diff(wide)[0] / 2))
    assert doppler_edges([], 0.1) is None


def test_read_dataset_info_declares_or_says_undeclared_never_guesses(tmp_path):
    pts = np.array([point_at(5.0, 0.0, 10.0)], np.float32)
    for name in ("declared", "no_domain", "no_file"):
        write_dataset(tmp_path / name, [Frame("a", pts, np.zeros((0, 7)), ())],
                      {"train": ["a"]})
    write_metadata(tmp_path / "declared", {"domain": "measured (IFR)"})
    write_metadata(tmp_path / "no_domain", {"radar": "ti-mmwcas"})
    assert read_dataset_info(tmp_path / "declared").domain == "measured (IFR)"
    assert read_dataset_info(tmp_path / "no_domain").domain == UNDECLARED == "undeclared"
    assert read_dataset_info(tmp_path / "no_file") == DatasetInfo()


def test_artefact_settings_reject_overlapping_control_windows():
    with pytest.raises(ValueError, match="sidelobe_control_offset_bins"):
        ArtefactSettings(sidelobe_range_tolerance_bins=2, sidelobe_control_offset_bins=4)
    with pytest.raises(ValueError, match="doppler_bin_mps"):
        ArtefactSettings(doppler_bin_mps=0.0)
