"""`sim2radar demo` and `sim2radar simulate` through Typer's CliRunner."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from sim2radar.cli import app
from storage import ArtifactStore, radar_frames_from_table

runner = CliRunner()


def test_demo_writes_parquet_png_and_summary(prefect_server, tmp_path):
    out = tmp_path / "out"
    result = runner.invoke(app, ["demo", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "points per frame" in result.output and str(out / "store") in result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"]["failed"] == 0
    (scene,) = summary["scenes"]
    store = ArtifactStore(out / "store")
    frames = radar_frames_from_table(store.read("radar_points", scene["artifacts"]["radar_points"]))
    assert len(frames) == 3 and all(len(f.points) > 20 for f in frames)
    assert all(len(f.boxes) == 3 and f.box_labels == ["door"] * 3 for f in frames)
    pngs = sorted((out / "bev").glob("*.png"))
    assert len(pngs) == 3 and all(p.read_bytes()[:4] == b"\x89PNG" for p in pngs)
    assert store.manifest("demo").counts()["ok"] == 1


def test_simulate_exit_codes_and_outputs(plate_scene, broken_scenes, tmp_path):
    store = tmp_path / "store"
    args = ["simulate", str(plate_scene), str(broken_scenes["missing"]), "--out", str(store), "--no-prefect"]
    result = runner.invoke(app, args + ["--json", str(tmp_path / "s.json")])
    assert result.exit_code == 0, result.output  # failures are recorded, not fatal by default
    assert "1 computed, 0 cached (skipped), 1 failed" in result.output
    assert "mesh file not found" in result.output
    assert len(list((tmp_path / "bev").glob("plate_f*.png"))) == 2  # default: next to the store
    again = runner.invoke(app, args + ["--strict"])
    assert again.exit_code == 1 and "0 computed, 1 cached (skipped), 1 failed" in again.output
    bad = runner.invoke(app, ["simulate", str(plate_scene), "--radar", "no-such-radar", "--out", str(store)])
    assert bad.exit_code == 2 and "presets" in bad.output
