"""The dashboard's sim–real gap section (sim2radar/experiment/dashboard/gap.py, gap_plots.py):
the tables of gap/gap.json, its figures drawn with Plotly from the report's numbers (a real
``sim2radar gap`` report of two constructed one-frame datasets), and an older report's figures
shown as its PNGs, with the page saying why.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sim2radar.experiment.dashboard import dashboard_data, load_sweep, render_html
from tests.experiment.test_dashboard import _embedded, make_sweep


@pytest.fixture
def sweep_dir(tmp_path):
    """test_dashboard.py's constructed sweep; its gap.json is an older report's: azimuth,
    range and intensity numbers, overlay.png and azimuth.png."""
    return make_sweep(tmp_path / "t")


def test_gap_figures_without_numbers_are_their_png_and_bad_entries_are_warned(sweep_dir):
    """The fixture's gap.json (an older report) holds the azimuth and range numbers but not the
    overlay's: azimuth and range are drawn from the numbers (their PNGs are not read, range.png
    need not exist), the overlay is its PNG, and the page says why."""
    import base64

    doc = json.loads((sweep_dir / "gap/gap.json").read_text())
    doc["figures"]["points"] = "points.png"                 # no numbers, and no file either
    (sweep_dir / "gap/gap.json").write_text(json.dumps(doc))
    sweep = load_sweep(sweep_dir)
    assert set(sweep.gap_images) == {"overlay"}
    uri = sweep.gap_images["overlay"]
    assert uri.startswith("data:image/png;base64,")
    assert base64.b64decode(uri.split(",", 1)[1]) == (sweep_dir / "gap/overlay.png").read_bytes()
    text = " ".join(sweep.warnings)
    assert "points.png: missing" in text                     # named in gap.json, not there
    assert "range.png" not in text                           # drawn from the numbers
    assert "'../sweep.json' is not a file name" in text        # no path escapes the gap folder
    gap = dashboard_data(sweep)["gap"]
    assert [f["name"] for f in gap["figures"]] == ["azimuth", "range", "intensity"]
    assert [i["name"] for i in gap["images"]] == ["overlay"]
    assert "overlay" in gap["image_note"] and "Rerun `sim2radar gap" in gap["image_note"]
    # the azimuth figure is the report's histogram in %: one step per bin, the last repeated
    az = {t["meta"]["side"]: t for t in gap["figures"][0]["figure"]["data"]}
    assert az["sim"]["x"] == [-60, 0, 60] and az["sim"]["y"] == [50.0, 50.0, 50.0]
    assert az["real"]["y"] == [40.0, 60.0, 60.0]
    assert "80.5°" in az["sim"]["name"] and "110.0°" in az["real"]["name"]


def _gap_report_into(sweep: Path) -> dict:
    """A real ``sim2radar gap`` report in ``sweep/gap``: SIM, undeclared, 4 points per frame
    of which 3 sit on a 40 dB point's range 20 dB weaker at 20°-40° (angle-sidelobe arcs), no
    Doppler; REAL, declared measured, its radar 1 m above the floor, 1 of its 4 points below
    it, 2 beyond 8 m, Doppler 0, 0, 0.5, -1 m/s."""
    from sim2radar.datasets import Frame, write_dataset, write_metadata
    from sim2radar.evaluate.gap import write_gap_report

    def at(r, az_deg, db, z=0.0, *extra):
        a = np.radians(az_deg)
        h = np.sqrt(r * r - z * z)
        return [h * np.cos(a), h * np.sin(a), z, db, *extra]

    sim = np.array([at(4.0, 0, 40), at(4.0, 20, 20), at(4.0, -30, 20), at(4.0, 40, 20)],
                   np.float32)
    real = np.array([at(3.0, 0, 30, -1.5, 0.0), at(5.0, 10, 30, 0.0, 0.0),
                     at(9.0, -10, 30, 0.0, 0.5), at(9.5, 20, 30, 0.0, -1.0)], np.float32)
    data = sweep / "data"
    for name, pts in (("sim", sim), ("real", real)):
        write_dataset(data / name, [Frame("f0", pts, np.zeros((0, 7)), ())], {"train": ["f0"]})
    write_metadata(data / "real", {"domain": "measured", "radar_height_m": 1.0})
    write_metadata(data / "sim", {"point_geometry": {"behind_share": 0.5, "beyond_share": 0.25},
                                  "labels_vs_truth": {"recall": 0.5, "precision": 1.0,
                                                      "width_error_m": 0.12}})
    return write_gap_report(data / "sim", data / "real", sweep / "gap")


def test_gap_section_shows_the_artefact_figures_and_artefacts_png(tmp_path):
    sweep = make_sweep(tmp_path / "a")
    doc = _gap_report_into(sweep)
    data = load_sweep(sweep)
    assert data.gap_images == {} and not data.warnings     # every figure from its numbers
    gap = dashboard_data(data)
    rows = {r[0]: r[1:] for r in gap["gap"]["rows"]}
    assert rows["domain (dataset.json)"] == ["undeclared", "measured"]
    assert rows["sidelobe-bin share / control"] == ["75.0 % / 0.0 %", "0.0 % / 0.0 %"]
    sim_doppler, real_doppler = rows["Doppler: moving share"]
    assert "no Doppler" in sim_doppler and sim_doppler == doc["artefacts"]["sim"]["doppler_note"]
    assert real_doppler == "50.0 % (median |v| 0.25 m/s)"
    assert rows["range > 8 m"] == ["0.0 %", "50.0 %"]
    below_sim, below_real = rows["> 0.1 m below the floor"]
    assert "floor height unknown" in below_sim and below_real == "25.0 %"
    # the fidelity rows: what SIM's dataset.json measured; REAL (measured) has no truth
    assert rows["points > 1 m behind the first true surface"] == [
        "50.0 %", "not measured (no true geometry)"]
    assert rows["points beyond 0.85 R_max"][0] == "25.0 %"
    assert rows["door labels vs true doors: recall / precision"] == [
        "50.0 % / 100.0 % (width error 0.12 m)", "—"]
    assert rows["azimuth covered (1–99 %)"][0].startswith("-")
    facts = dict(gap["gap"]["facts"])
    assert "13 dB stronger" in facts["sidelobe share"]
    assert any(k == "reading" and "SIM 50 %" in v for k, v in gap["gap"]["facts"])
    assert [f["name"] for f in gap["gap"]["figures"]].count("artefacts") == 1
    page = render_html(gap)
    assert _embedded(page)["gap"]["rows"] == gap["gap"]["rows"]
    json.dumps(gap, allow_nan=False)


def _gap_figure(gap: dict, name: str) -> dict:
    return next(f["figure"] for f in gap["figures"] if f["name"] == name)


def test_gap_figures_are_drawn_from_the_reports_numbers(tmp_path):
    """Every figure of a current report is a Plotly figure of gap.json's numbers (no PNG):
    the overlay's points are the frame's, the artefact bars the shares in %, a share a
    dataset cannot measure is written "unknown" (not drawn as a bar of 0)."""
    sweep = make_sweep(tmp_path / "a")
    doc = _gap_report_into(sweep)
    gap = dashboard_data(load_sweep(sweep))["gap"]
    assert [f["name"] for f in gap["figures"]] == ["overlay", "points", "azimuth", "range",
                                                   "intensity", "artefacts", "fidelity"]
    assert gap["images"] == [] and gap["image_note"] is None
    overlay = _gap_figure(gap, "overlay")
    bev = {t["meta"]["side"]: t for t in overlay["data"]
           if t["meta"].get("view") == "bev" and t["meta"]["side"]}
    # bird's-eye view: x forward up the page (the plot's y), y left along the reversed x axis
    np.testing.assert_allclose(bev["sim"]["y"], [p[0] for p in doc["overlay"]["sim_points"]])
    np.testing.assert_allclose(bev["real"]["x"], [p[1] for p in doc["overlay"]["real_points"]])
    assert overlay["layout"]["xaxis"]["autorange"] == "reversed"
    points = {t["meta"]["side"]: t for t in _gap_figure(gap, "points")["data"]}
    assert points["sim"]["x"] == [4] and points["real"]["x"] == [4]
    sidelobe = next(t for t in _gap_figure(gap, "artefacts")["data"]
                    if t["meta"].get("measure") == "sidelobe_share")
    assert sidelobe["y"] == [75.0, 0.0]                        # sim, real [%]
    shares = {t["meta"]["side"]: t for t in _gap_figure(gap, "artefacts")["data"]
              if t["meta"].get("measure") == "shares"}
    assert shares["real"]["y"] == [50.0, 25.0]                 # beyond 8 m, below the floor
    assert shares["sim"]["text"][1] == "unknown"               # no floor height: not 0
    titles = " ".join(a["text"] for a in _gap_figure(gap, "artefacts")["layout"]["annotations"])
    assert "sim: no Doppler column (not drawn)" in titles
    doppler = [t for t in _gap_figure(gap, "artefacts")["data"]
               if t["meta"]["side"] == "real" and t.get("xaxis") == "x2"]
    assert len(doppler) == 1
    fid = {t["meta"]["side"]: t for t in _gap_figure(gap, "fidelity")["data"]
           if t["meta"]["measure"] == "shares"}
    assert fid["sim"]["y"][:2] == [50.0, 25.0] and fid["real"]["text"][0] == "unknown"


def test_an_older_gap_report_shows_its_overlay_and_points_as_pngs_and_says_so(tmp_path):
    sweep = make_sweep(tmp_path / "a")
    doc = _gap_report_into(sweep)
    old = {k: v for k, v in doc.items() if k not in ("overlay", "points")}
    (sweep / "gap/gap.json").write_text(json.dumps(old))
    data = load_sweep(sweep)
    assert set(data.gap_images) == {"overlay", "points"} and not data.warnings
    gap = dashboard_data(data)["gap"]
    assert [i["name"] for i in gap["images"]] == ["overlay", "points"]
    assert [f["name"] for f in gap["figures"]] == ["azimuth", "range", "intensity",
                                                   "artefacts", "fidelity"]
    assert "overlay, points" in gap["image_note"]


def test_gap_section_of_an_older_report_without_artefacts_shows_dashes(sweep_dir):
    gap = dashboard_data(load_sweep(sweep_dir))["gap"]
    rows = {r[0]: r[1:] for r in gap["rows"]}
    for label in ("domain (dataset.json)", "sidelobe-bin share / control",
                  "Doppler: moving share", "range > 8 m", "> 0.1 m below the floor"):
        assert rows[label] == ["—", "—"], label
    assert ["points per frame (mean)", "300.5", "1,200.0"] in gap["rows"]   # the rest as before
    assert "sidelobe share" not in dict(gap["facts"])
    render_html(dashboard_data(load_sweep(sweep_dir)))
