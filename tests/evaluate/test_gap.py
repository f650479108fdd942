"""The sim–real gap report (`sim2radar/evaluate/gap.py`, `sim2radar gap`).

Synthetic datasets with known answers: a "sim" whose points lie within ±15° azimuth and a
"real" spread over ±60° (the paper's ~31° vs 120°), 250 vs 2,000 points per frame (12.5 %),
sim intensities around -60 dB and real ones around +20 dB.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.datasets import DatasetError, Frame, write_dataset, write_metadata
from sim2radar.evaluate.artefacts import ArtefactSettings
from sim2radar.evaluate.gap import (
    FIGURES,
    GapSettings,
    chamfer_pairs,
    compute_gap,
    effective_fov,
    histogram_edges,
    write_gap_report,
)
from sim2radar.radar.intensity import fit_intensity_match
from tests.evaluate.test_artefacts import arc_frame, point_at, uniform_frame

SIM_HALF_DEG, REAL_HALF_DEG = 15.0, 60.0
SIM_POINTS, REAL_POINTS = 250, 2000
SHARED = [f"world_000000_f{i:03d}" for i in range(4)]
REAL_ONLY = [f"world_000001_f{i:03d}" for i in range(2)]


def _points(rng, n: int, half_deg: float, db_mean: float, db_std: float,
            doppler: bool = False) -> np.ndarray:
    """n points uniform in azimuth over ±half_deg, range 1-10 m, with intensities [dB]."""
    az = np.radians(rng.uniform(-half_deg, half_deg, n))
    r = rng.uniform(1.0, 10.0, n)
    z = rng.uniform(-1.0, 1.5, n)
    cols = [r * np.cos(az), r * np.sin(az), z, rng.normal(db_mean, db_std, n)]
    if doppler:
        cols.append(rng.normal(0.0, 0.3, n))
    return np.column_stack(cols).astype(np.float32)


def _box() -> np.ndarray:
    return np.array([[4.0, 1.5, 0.0, 1.0, 0.2, 2.0, 0.0]], np.float32)


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    """SIM (4 frames, all shared) and REAL (6 frames: 4 shared, train = 3 shared + 1 other).

    REAL's val/test frames are 30 dB brighter than its train frames: a match fitted on train
    only maps the sim median onto the train median (20 dB), not the all-frames one."""
    rng = np.random.default_rng(0)
    root = tmp_path_factory.mktemp("gap")
    sim_frames = [Frame(fid, _points(rng, SIM_POINTS, SIM_HALF_DEG, -60.0, 5.0), _box(), ("door",))
                  for fid in SHARED]
    train = SHARED[:3] + REAL_ONLY[:1]
    real_frames = [Frame(fid, _points(rng, REAL_POINTS, REAL_HALF_DEG,
                                      20.0 if fid in train else 50.0, 8.0, doppler=True),
                         _box(), ("door",))
                   for fid in SHARED + REAL_ONLY]
    write_dataset(root / "sim", sim_frames, {"train": SHARED})
    write_dataset(root / "real", real_frames,
                  {"train": train, "val": [SHARED[3]], "test": REAL_ONLY[1:]})
    return root, {f.frame_id: f.points for f in sim_frames}, {f.frame_id: f.points
                                                               for f in real_frames}, train


@pytest.fixture(scope="module")
def report(datasets):
    root, *_ = datasets
    doc = write_gap_report(root / "sim", root / "real", root / "report")
    return root / "report", doc


# ------------------------------------------------------------------------------- pure parts


def test_effective_fov_of_uniform_sectors_is_95_percent_of_their_width():
    rng = np.random.default_rng(1)
    for width in (31.0, 120.0):
        fov = effective_fov(rng.uniform(-width / 2, width / 2, 50_000), 0.95)
        assert fov.width_deg == pytest.approx(0.95 * width, abs=0.01 * width)
        assert -width / 2 <= fov.lo_deg < fov.hi_deg <= width / 2


def test_effective_fov_ignores_sparse_outliers_and_wraps_through_180():
    core = np.linspace(-10.0, 10.0, 95)
    fov = effective_fov(np.concatenate([core, np.full(5, 80.0)]), 0.95)
    assert (fov.lo_deg, fov.hi_deg, fov.width_deg) == pytest.approx((-10.0, 10.0, 20.0))
    # points behind the radar, from 170° through 180° to -170°: a 20° interval, not 340°
    behind = np.mod(np.linspace(170.0, 190.0, 41) + 180.0, 360.0) - 180.0
    fov = effective_fov(behind, 1.0)
    assert fov.width_deg == pytest.approx(20.0)
    assert fov.lo_deg == pytest.approx(170.0)
    assert np.isnan(effective_fov(np.zeros(0)).width_deg)


def test_chamfer_of_a_frame_with_itself_is_zero_and_of_a_shifted_copy_is_the_shift():
    # a 1 m grid: a 0.1 m shift keeps every nearest neighbour the shifted twin
    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0), np.arange(3.0)), -1).reshape(-1, 3)
    shift = np.array([0.1, 0.0, 0.0])
    res = chamfer_pairs({"a": g, "b": g, "sim_only": g}, {"a": g, "b": g + shift, "real_only": g})
    assert res.pairs == 2 and sorted(res.per_frame) == ["a", "b"]
    assert res.per_frame["a"] == pytest.approx(0.0, abs=1e-12)
    assert res.per_frame["b"] == pytest.approx(0.1, abs=1e-9)
    assert res.mean_m == pytest.approx(0.05, abs=1e-9)
    assert chamfer_pairs({"a": g}, {"b": g}) is None


def test_matched_sim_intensities_follow_the_real_quantiles():
    rng = np.random.default_rng(2)
    sim = {"s": _points(rng, 4000, 15.0, -60.0, 5.0)}
    real = {"r": _points(rng, 4000, 60.0, 20.0, 8.0)}
    match = fit_intensity_match(sim["s"][:, 3], real["r"][:, 3])
    rep = compute_gap(sim, real, match)
    after = match.apply(sim["s"][:, 3])
    q = [0.1, 0.5, 0.9]
    np.testing.assert_allclose(np.quantile(after, q), np.quantile(real["r"][:, 3], q), atol=0.3)
    # histograms: before matching the two barely overlap; after, they nearly coincide
    tv_before = 0.5 * np.abs(rep.intensity_sim_before - rep.intensity_real).sum()
    tv_after = 0.5 * np.abs(rep.intensity_sim_after - rep.intensity_real).sum()
    assert tv_before > 0.99 and tv_after < 0.1
    assert rep.chamfer is None and rep.points_ratio == pytest.approx(1.0)


def test_histogram_edges_cover_the_span_and_respect_the_bin_cap():
    e = histogram_edges(-3.2, 17.0, 1.0)
    assert e[0] <= -3.2 and e[-1] >= 17.0 and np.allclose(np.diff(e), 1.0)
    e = histogram_edges(0.0, 1000.0, 0.25, max_bins=200)
    assert len(e) - 1 <= 200 and e[-1] >= 1000.0


# --------------------------------------------------------------------------------- report


def test_report_has_exactly_the_dashboard_structure(report):
    out, doc = report
    assert set(doc) == {"sim", "real", "points_ratio", "azimuth", "range", "intensity",
                        "chamfer", "overlay_frame", "overlay", "points", "artefacts",
                        "fidelity", "figures"}
    assert set(doc["overlay"]) == {"frame", "sim_frame", "real_frame", "title", "sim_points",
                                   "real_points", "boxes"}
    assert set(doc["points"]) == {"sim_counts", "real_counts"}
    fid = doc["fidelity"]
    assert set(fid) == {"sim", "real", "readings", "definitions"}
    for role in ("sim", "real"):
        assert set(fid[role]) == {
            "behind_share", "beyond_share", "points_per_label", "labels_empty",
            "labels_under_5", "azimuth_lo_deg", "azimuth_hi_deg", "label_recall",
            "label_precision", "label_width_error_m", "label_depth_error_m"}
        # no dataset.json with the true geometry's measures: not measured, never 0
        assert fid[role]["behind_share"] is None and fid[role]["label_recall"] is None
    assert all(isinstance(r, str) for r in fid["readings"]) and len(fid["readings"]) >= 4
    for role in ("sim", "real"):
        assert set(doc[role]) == {"root", "domain", "frames", "points_per_frame_mean",
                                  "points_per_frame_median"}
    art = doc["artefacts"]
    assert set(art) == {"settings", "definitions", "doppler_edges_mps", "sim", "real"}
    assert set(art["settings"]) == {
        "range_resolution_m", "sidelobe_min_drop_db", "sidelobe_min_separation_deg",
        "sidelobe_range_tolerance_bins", "sidelobe_control_offset_bins", "doppler_bin_mps",
        "far_range_m", "below_floor_margin_m"}
    assert set(art["definitions"]) == {"sidelobe", "doppler", "beyond_range", "below_floor"}
    for role in ("sim", "real"):
        assert set(art[role]) == {
            "points", "range_resolution_m", "range_resolution_from", "sidelobe_share",
            "sidelobe_control_share", "sidelobe_difference", "sidelobe_points",
            "sidelobe_control_points", "doppler", "doppler_note", "beyond_range_share",
            "below_floor_share", "radar_height_m", "below_floor_note"}
        assert set(art[role]["sidelobe_control_points"]) == {"plus", "minus", "either"}
    assert set(art["real"]["doppler"]) == {"fraction", "moving_share", "abs_median_mps"}
    assert set(doc["azimuth"]) == {"edges_deg", "sim_fraction", "real_fraction",
                                   "effective_fov_deg", "definition"}
    assert set(doc["azimuth"]["effective_fov_deg"]) == {"sim", "real"}
    assert set(doc["range"]) == {"edges_m", "sim_fraction", "real_fraction"}
    assert set(doc["intensity"]) == {"edges_db", "sim_before", "sim_after", "real", "fitted_on",
                                     "match"}
    assert set(doc["chamfer"]) == {"pairs", "mean_m", "per_frame"}
    assert doc["figures"] == FIGURES
    # the file on disk is the returned document, and every figure is a PNG
    assert json.loads((out / "gap.json").read_text()) == doc
    for name in FIGURES.values():
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    # histograms: one fraction per bin, every point in some bin
    for key, edges, fracs in (("azimuth", "edges_deg", ("sim_fraction", "real_fraction")),
                              ("range", "edges_m", ("sim_fraction", "real_fraction")),
                              ("intensity", "edges_db", ("sim_before", "sim_after", "real"))):
        for f in fracs:
            assert len(doc[key][f]) == len(doc[key][edges]) - 1
            assert sum(doc[key][f]) == pytest.approx(1.0), (key, f)


def test_report_measures_the_constructed_gap(report, datasets):
    _, doc = report
    _, sim, real, train = datasets
    assert doc["sim"]["frames"] == 4 and doc["real"]["frames"] == 6
    assert doc["sim"]["points_per_frame_mean"] == SIM_POINTS
    assert doc["real"]["points_per_frame_median"] == REAL_POINTS
    assert doc["points_ratio"] == pytest.approx(SIM_POINTS / REAL_POINTS)  # 12.5 %
    # the points figure's numbers: every analysed frame's count, in frame order
    assert doc["points"] == {"sim_counts": [SIM_POINTS] * 4, "real_counts": [REAL_POINTS] * 6}
    fov = doc["azimuth"]["effective_fov_deg"]
    assert fov["sim"] == pytest.approx(0.95 * 2 * SIM_HALF_DEG, abs=1.0)  # ~28.5°, "31°"
    assert fov["real"] == pytest.approx(0.95 * 2 * REAL_HALF_DEG, abs=2.0)  # ~114°, "120°"
    assert "95 %" in doc["azimuth"]["definition"]
    az = np.asarray(doc["azimuth"]["edges_deg"])
    sim_frac = np.asarray(doc["azimuth"]["sim_fraction"])
    assert sim_frac[(az[:-1] >= SIM_HALF_DEG) | (az[1:] <= -SIM_HALF_DEG)].sum() == 0
    # range: every point between 1 and 10 m (plus its height)
    r_edges = np.asarray(doc["range"]["edges_m"])
    real_r = np.asarray(doc["range"]["real_fraction"])
    assert real_r[r_edges[1:] <= 1.0].sum() == 0 and real_r[r_edges[:-1] > 10.2].sum() == 0


def test_intensity_match_is_fitted_on_the_real_train_split_only(report, datasets):
    _, doc = report
    _, sim, real, train = datasets
    assert "train split" in doc["intensity"]["fitted_on"]
    m = doc["intensity"]["match"]
    assert m["n_target"] == len(train) * REAL_POINTS and m["n_source"] == 4 * SIM_POINTS
    # the matched sim median is the train frames' (20 dB), not all real frames' (~30 dB)
    edges = np.asarray(doc["intensity"]["edges_db"])
    cdf = np.cumsum(doc["intensity"]["sim_after"])
    median_bin = edges[np.searchsorted(cdf, 0.5)]
    train_db = np.concatenate([real[f][:, 3] for f in train])
    assert abs(median_bin - np.median(train_db)) <= 2 * (edges[1] - edges[0])


def test_shared_ids_give_chamfer_pairs_and_the_overlay_frame(report, datasets):
    _, doc = report
    _, sim, real, _ = datasets
    ch = doc["chamfer"]
    assert ch["pairs"] == len(SHARED) and sorted(ch["per_frame"]) == SHARED
    assert ch["mean_m"] == pytest.approx(np.mean(list(ch["per_frame"].values())))
    # sim (±15°) points sit inside the real cloud, but most real points (±60°) are far from
    # any sim point: the Chamfer distance is well above zero
    assert all(d > 0.1 for d in ch["per_frame"].values())
    assert doc["overlay_frame"] in SHARED
    # the overlay's numbers: that frame's points to 1 mm and 0.1 dB, and its label box
    ov = doc["overlay"]
    fid = doc["overlay_frame"]
    assert ov["frame"] == ov["sim_frame"] == ov["real_frame"] == fid
    for key, pts in (("sim_points", sim[fid]), ("real_points", real[fid])):
        got = np.asarray(ov[key])
        assert got.shape == (len(pts), 4)
        np.testing.assert_allclose(got[:, :3], pts[:, :3], atol=5e-4 + 1e-6)
        np.testing.assert_allclose(got[:, 3], pts[:, 3], atol=0.05 + 1e-5)
    np.testing.assert_allclose(ov["boxes"], _box(), atol=1e-6)
    assert f"frame {fid}" in ov["title"]


def test_no_shared_ids_and_no_train_split(tmp_path):
    rng = np.random.default_rng(3)
    write_dataset(tmp_path / "sim", [Frame("s0", _points(rng, 100, 15, -60, 5),
                                           np.zeros((0, 7)), ())], {"train": ["s0"]})
    write_dataset(tmp_path / "real", [Frame("r0", _points(rng, 400, 60, 20, 8),
                                            np.zeros((0, 7)), ())], {"val": ["r0"]})
    doc = write_gap_report(tmp_path / "sim", tmp_path / "real", tmp_path / "out")
    assert doc["chamfer"] is None and doc["overlay_frame"] is None
    ov = doc["overlay"]      # different scenes: the first frame of each, no shared id
    assert (ov["frame"], ov["sim_frame"], ov["real_frame"]) == (None, "s0", "r0")
    assert len(ov["sim_points"]) == 100 and len(ov["real_points"]) == 400
    assert "different scenes" in ov["title"]
    assert "no ImageSets/train.txt" in doc["intensity"]["fitted_on"]
    assert doc["points_ratio"] == pytest.approx(0.25)
    assert (tmp_path / "out" / "overlay.png").is_file()


def test_cli_prints_a_summary_and_honours_max_frames(datasets, tmp_path):
    root, *_ = datasets
    r = CliRunner().invoke(app, ["gap", str(root / "sim"), str(root / "real"), "--out",
                                 str(tmp_path / "g"), "--max-frames", "2"],
                           env={"COLUMNS": "400"})
    assert r.exit_code == 0, r.output
    assert "points ratio sim/real: 12.5 %" in r.output
    assert "Chamfer (2 shared frames)" in r.output
    # one artefact line per domain: sim has no Doppler column, real does; no floor heights
    sim_line, real_line = (next(ln for ln in r.output.splitlines()
                                if ln.startswith(f"{role:4s} artefacts")) for role in ("sim", "real"))
    assert "[domain: undeclared]" in sim_line and "[domain: undeclared]" in real_line
    assert "no Doppler" in sim_line and "Doppler moving" in real_line
    assert "sidelobe bins" in sim_line and "vs control" in sim_line
    assert "range > 8 m" in real_line
    assert "below floor: unknown" in sim_line
    assert "artefacts.png" in r.output
    doc = json.loads((tmp_path / "g" / "gap.json").read_text())
    assert doc["sim"]["frames"] == 2 and doc["real"]["frames"] == 2


def test_cli_exits_2_with_one_clear_line_on_a_missing_or_malformed_dataset(datasets, tmp_path):
    root, *_ = datasets
    missing = tmp_path / "nowhere"
    r = CliRunner().invoke(app, ["gap", str(missing), str(root / "real"), "--out",
                                 str(tmp_path / "g")], env={"COLUMNS": "400"})
    assert r.exit_code == 2
    assert "Traceback" not in r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(missing) in lines[0] and "SIM" in lines[0]
    # x y z without intensity: the file is named, with what it needs
    rng = np.random.default_rng(4)
    write_dataset(tmp_path / "xyz", [Frame("a", _points(rng, 50, 15, 0, 1)[:, :3],
                                           np.zeros((0, 7)), ())], {"train": ["a"]})
    r = CliRunner().invoke(app, ["gap", str(tmp_path / "xyz"), str(root / "real"), "--out",
                                 str(tmp_path / "g")], env={"COLUMNS": "400"})
    assert r.exit_code == 2 and "a.npy" in r.output and "intensity" in r.output, r.output
    assert not (tmp_path / "g").exists()


# ------------------------------------- artefact figures in the report (measures: test_artefacts.py)


def test_doppler_histogram_when_present_and_null_with_a_note_when_not(tmp_path):
    v = np.array([0.0, 0.02, -0.04, 0.3, -1.0, 0.06])
    with_d = np.column_stack([np.array([point_at(2.0 + i, 0.0, 10.0) for i in range(6)]), v])
    without = np.array([point_at(2.0 + i, 0.0, 10.0) for i in range(6)])
    write_dataset(tmp_path / "sim", [Frame("a", without.astype(np.float32), np.zeros((0, 7)),
                                           ())], {"train": ["a"]})
    write_dataset(tmp_path / "real", [Frame("a", with_d.astype(np.float32), np.zeros((0, 7)),
                                            ())], {"train": ["a"]})
    doc = write_gap_report(tmp_path / "sim", tmp_path / "real", tmp_path / "out")
    art = doc["artefacts"]
    assert art["sim"]["doppler"] is None and "no Doppler" in art["sim"]["doppler_note"]
    real = art["real"]["doppler"]
    assert art["real"]["doppler_note"] is None
    assert real["moving_share"] == pytest.approx(3 / 6)              # 0.3, -1.0, 0.06
    assert real["abs_median_mps"] == pytest.approx(0.05, abs=1e-6)   # (0.04 + 0.06) / 2
    edges = np.asarray(art["doppler_edges_mps"])
    np.testing.assert_allclose(np.diff(edges), 0.1)
    assert edges[0] <= -1.0 and edges[-1] > 0.3
    zero = np.flatnonzero((edges[:-1] < 0) & (edges[1:] > 0))[0]     # the bin centred on 0
    assert edges[zero] == pytest.approx(-0.05) and real["fraction"][zero] == pytest.approx(0.5)
    assert sum(real["fraction"]) == pytest.approx(1.0)
    assert (tmp_path / "out" / "artefacts.png").read_bytes()[:4] == b"\x89PNG"


def test_below_floor_share_needs_the_radar_height(tmp_path):
    # radar 1.0 m above the floor: z = -1.2 and -1.11 are > 0.1 m below it, -1.05 is not
    z = [-1.05, -1.2, -0.5, -1.11, 0.3]
    pts = np.array([point_at(5.0, 0.0, 10.0, zi) for zi in z], np.float32)
    for name in ("high", "nothing"):
        write_dataset(tmp_path / name, [Frame("a", pts, np.zeros((0, 7)), ())],
                      {"train": ["a"]})
    write_metadata(tmp_path / "high", {"domain": "proxy-real", "radar_height_m": 1.0})
    doc = write_gap_report(tmp_path / "high", tmp_path / "nothing", tmp_path / "out")
    sim, real = doc["artefacts"]["sim"], doc["artefacts"]["real"]
    assert sim["below_floor_share"] == pytest.approx(2 / 5) and sim["radar_height_m"] == 1.0
    assert sim["below_floor_note"] is None
    assert real["below_floor_share"] is None and real["radar_height_m"] is None
    assert "floor height unknown" in real["below_floor_note"]
    # a bad value names the file and the key
    write_metadata(tmp_path / "high", {"radar_height_m": "1 m"})
    with pytest.raises(DatasetError, match=r"dataset\.json: radar_height_m"):
        write_gap_report(tmp_path / "high", tmp_path / "nothing", tmp_path / "out2")


def test_report_domain_is_declared_or_undeclared_never_guessed(tmp_path):
    pts = np.array([point_at(5.0, 0.0, 10.0)], np.float32)
    for name in ("declared", "no_file"):
        write_dataset(tmp_path / name, [Frame("a", pts, np.zeros((0, 7)), ())],
                      {"train": ["a"]})
    write_metadata(tmp_path / "declared", {"domain": "measured (IFR)"})
    doc = write_gap_report(tmp_path / "declared", tmp_path / "no_file", tmp_path / "out")
    assert doc["sim"]["domain"] == "measured (IFR)" and doc["real"]["domain"] == "undeclared"


def test_range_resolution_comes_from_dataset_json(tmp_path):
    # a weak point 0.076 m beyond a strong one: 2 bins of 0.038 m (no sidelobe), but within
    # one bin of 0.1 m
    pts = np.array([point_at(4.0, 0.0, 40.0), point_at(4.076, 30.0, 20.0)], np.float32)
    for name in ("coarse", "default"):
        write_dataset(tmp_path / name, [Frame("a", pts, np.zeros((0, 7)), ())],
                      {"train": ["a"]})
    write_metadata(tmp_path / "coarse", {"range_resolution_m": 0.1})
    doc = write_gap_report(tmp_path / "coarse", tmp_path / "default", tmp_path / "out")
    coarse, default = doc["artefacts"]["sim"], doc["artefacts"]["real"]
    assert (coarse["range_resolution_m"], coarse["range_resolution_from"]) == (0.1,
                                                                               "dataset.json")
    assert default["range_resolution_m"] == 0.038
    assert coarse["sidelobe_share"] == 0.5 and default["sidelobe_share"] == 0.0


def test_report_of_arc_and_uniform_datasets(tmp_path):
    rng = np.random.default_rng(13)
    ids = [f"f{i}" for i in range(4)]
    write_dataset(tmp_path / "arcs", [Frame(f, arc_frame(rng), np.zeros((0, 7)), ())
                                      for f in ids], {"train": ids})
    write_dataset(tmp_path / "clean", [Frame(f, uniform_frame(rng, 1500), np.zeros((0, 7)),
                                             ()) for f in ids], {"train": ids})
    doc = write_gap_report(tmp_path / "arcs", tmp_path / "clean", tmp_path / "out")
    arcs, clean = doc["artefacts"]["sim"], doc["artefacts"]["real"]
    assert arcs["sidelobe_share"] == pytest.approx(0.8) and arcs["sidelobe_control_share"] == 0
    assert arcs["sidelobe_points"] == 4 * 60
    assert abs(clean["sidelobe_difference"]) < 0.03
    assert clean["beyond_range_share"] == pytest.approx(2 / 9, abs=0.03)  # uniform 1-10 m
    assert doc["artefacts"]["doppler_edges_mps"] is None            # neither has Doppler


def test_report_carries_the_artefact_settings_it_was_given(tmp_path):
    pts = np.array([point_at(5.0, 0.0, 10.0), point_at(9.0, 10.0, 10.0)], np.float32)
    for name in ("sim", "real"):
        write_dataset(tmp_path / name, [Frame("a", pts, np.zeros((0, 7)), ())],
                      {"train": ["a"]})
    assert GapSettings().artefacts == ArtefactSettings()
    s = GapSettings(artefacts=ArtefactSettings(far_range_m=10.0))
    doc = write_gap_report(tmp_path / "sim", tmp_path / "real", tmp_path / "out", settings=s)
    art = doc["artefacts"]
    assert art["settings"]["far_range_m"] == 10.0 and "> 10 m" in art["definitions"]["beyond_range"]
    assert art["sim"]["beyond_range_share"] == 0.0                   # 9 m is not beyond 10 m
    with pytest.raises(TypeError, match="ArtefactSettings"):
        GapSettings(artefacts={"far_range_m": 10.0})


def test_fidelity_section_reads_what_the_datasets_measured(datasets, tmp_path):
    """Each side's dataset.json point_geometry / labels_vs_truth (written by the factory for
    procedural worlds) reach gap.json, the readings and the dashboard; the door figures are
    counted from the exported points and labels."""
    root, sim_pts, real_pts, _ = datasets
    import shutil

    for side, share in (("sim", 0.4), ("real", 0.2)):
        shutil.copytree(root / side, tmp_path / side)
        write_metadata(tmp_path / side, {
            "domain": side, "point_geometry": {"behind_share": share, "beyond_share": 0.05},
            "labels_vs_truth": {"recall": 0.5, "precision": 0.75, "width_error_m": 0.2,
                                "depth_error_m": 0.03}})
    doc = write_gap_report(tmp_path / "sim", tmp_path / "real", tmp_path / "report")
    fid = doc["fidelity"]
    assert fid["sim"]["behind_share"] == pytest.approx(0.4)
    assert fid["real"]["behind_share"] == pytest.approx(0.2)
    assert fid["sim"]["label_recall"] == pytest.approx(0.5)
    assert any("SIM 40 %, REAL 20 % (2.0x)" in r for r in fid["readings"])
    box = _box()[0]
    c, s_ = math.cos(box[6]), math.sin(box[6])

    def inside(p):
        d = p[:, :3] - box[:3]
        along, across = d[:, 0] * c + d[:, 1] * s_, -d[:, 0] * s_ + d[:, 1] * c
        return int(np.sum((np.abs(along) <= box[3] / 2) & (np.abs(across) <= box[4] / 2)
                          & (np.abs(d[:, 2]) <= box[5] / 2)))

    want = float(np.median([inside(p) for p in sim_pts.values()]))
    assert fid["sim"]["points_per_label"] == pytest.approx(want)
    assert (tmp_path / "report" / "fidelity.png").read_bytes()[:4] == b"\x89PNG"
