"""`sim2radar demo` (procedural worlds, the main job) and `sim2radar simulate` through Typer's CliRunner."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from sim2radar.cli import app
from storage import ArtifactStore

runner = CliRunner()


def test_demo_runs_procedural_worlds_end_to_end(prefect_server, tmp_path):
    out = tmp_path / "out"
    args = ["demo", "--out", str(out), "--worlds", "1", "--frames", "1",
            "--width", "160", "--height", "120", "--spp", "4"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert str(out / "store") in result.output and "preview" in result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"]["failed"] == 0 and summary["frame_counts"]["failed"] == 0
    for geometry in ("ground_truth", "reconstructed"):
        assert summary["geometry"][geometry]["frames"] == 1
        assert summary["geometry"][geometry]["points_per_frame"] > 20  # radar saw the corridor
        assert (out / "openpcdet" / geometry / "ImageSets" / "train.txt").is_file()
    # ground-truth labels are the world's doors in the radar's view
    assert summary["geometry"]["ground_truth"]["label_recall"] == 1.0
    pngs = sorted((out / "bev").glob("*.png")) + [out / "preview_world0.png"]
    assert len(pngs) >= 3 and all(p.read_bytes()[:4] == b"\x89PNG" for p in pngs)
    store = ArtifactStore(out / "store")
    assert store.manifest("demo").counts()["failed"] == 0
    assert store.keys("dataset_frames")


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
