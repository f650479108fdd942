"""`sim2radar demo` (procedural worlds, the main job) and `sim2radar simulate` through Typer's CliRunner."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.storage import ArtifactStore

runner = CliRunner()


def test_demo_runs_procedural_worlds_end_to_end(prefect_server, tmp_path):
    """The main job, small: simulated domain, proxy-real domain, gap report, a smoke sweep and
    its dashboard, all from one command."""
    out = tmp_path / "out"
    args = ["demo", "--out", str(out), "--worlds", "3", "--frames", "1",
            "--reference-worlds", "3", "--reference-frames", "2", "--profile", "smoke",
            "--width", "160", "--height", "120", "--spp", "4"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "dashboard" in result.output and "preview" in result.output
    summary = json.loads((out / "summary.json").read_text())
    sim, real = summary["generate"], summary["reference"]
    assert sim["counts"]["failed"] == 0 and sim["frame_counts"]["failed"] == 0
    for geometry in ("ground_truth", "reconstructed"):
        assert sim["geometry"][geometry]["frames"] == 3
        assert sim["geometry"][geometry]["points_per_frame"] > 20  # radar saw the corridor
        assert (out / "openpcdet" / geometry / "ImageSets" / "train.txt").is_file()
    # ground-truth labels are the world's doors the radar sees
    assert sim["geometry"]["ground_truth"]["label_recall"] == 1.0
    # the proxy-real domain: labelled as a proxy, 5 columns (Doppler of the walking rig)
    ref = real["geometry"]["ground_truth"]
    assert real["counts"] == {"ok": 3, "skipped": 0, "failed": 0} and ref["frames"] == 6
    assert ref["points_per_frame"] > 20
    meta = json.loads((out / "openpcdet" / "proxy_real" / "dataset.json").read_text())
    assert meta["domain"] == "proxy-real (reference radar simulation)"
    assert meta["point_columns"][-1] == "doppler_mps" and meta["point_geometry"]["points"] > 0
    pts = np.load(next((out / "openpcdet" / "proxy_real" / "points").glob("*.npy")))
    assert pts.shape[1] == 5 and np.any(pts[:, 4] != 0)
    gap = summary["gap"]
    assert 0 < gap["points_ratio"] < 1 and (out / "sweeps" / "demo" / "gap" / "gap.json").is_file()
    assert summary["sweep"]["counts"]["failed"] == 0 and summary["sweep"]["counts"]["ok"] > 0
    html = (out / "sweeps" / "demo" / "dashboard.html").read_text()
    assert "proxy-real" in html
    pngs = sorted((out / "bev").glob("*.png")) + [out / "preview_world0.png"]
    assert len(pngs) >= 3 and all(p.read_bytes()[:4] == b"\x89PNG" for p in pngs)
    store = ArtifactStore(out / "store")
    assert store.manifest("demo").counts()["failed"] == 0
    assert store.keys("dataset_frames")


def test_simulate_exit_codes_and_outputs(plate_scene, broken_scenes, tmp_path):
    store = tmp_path / "store"
    args = ["simulate", str(plate_scene), str(broken_scenes["missing"]), "--out", str(store), "--no-prefect"]
    result = runner.invoke(app, args + ["--json", str(tmp_path / "s.json")])
    # a failed scene is recorded while the others finish, and the exit status says it failed
    # (as the Prefect run does, which ends Failed)
    assert result.exit_code == 1, result.output
    assert "1 computed, 0 cached (skipped), 1 failed" in result.output
    assert "mesh file not found" in result.output
    assert "1 of 2 scenes failed" in result.output and "--allow-failures exits 0" in result.output
    assert len(list((tmp_path / "bev").glob("plate_f*.png"))) == 2  # default: next to the store
    assert json.loads((tmp_path / "s.json").read_text())["counts"]["failed"] == 1
    again = runner.invoke(app, args + ["--allow-failures"])
    assert again.exit_code == 0 and "0 computed, 1 cached (skipped), 1 failed" in again.output
    fine = runner.invoke(app, ["simulate", str(plate_scene), "--out", str(store), "--no-prefect"])
    assert fine.exit_code == 0, fine.output
    bad = runner.invoke(app, ["simulate", str(plate_scene), "--radar", "no-such-radar", "--out", str(store)])
    assert bad.exit_code == 2 and "presets" in bad.output


def test_simulate_bad_scene_is_recorded_without_a_traceback(prefect_server, plate_scene,
                                                             broken_scenes, tmp_path):
    """Through the Prefect engine, as a user runs it (a subprocess: Prefect's own console
    logging): a broken scene is a failed manifest row and one line of the summary while the
    others finish, and no traceback is printed."""
    from prefect.settings import PREFECT_API_URL

    repo = Path(__file__).resolve().parents[2]
    store = tmp_path / "store"
    env = {**os.environ, "PREFECT_API_URL": PREFECT_API_URL.value(), "COLUMNS": "400",
           "PREFECT_LOGGING_LEVEL": "WARNING", "PYTHONPATH": str(repo)}
    args = ["simulate", str(plate_scene), str(broken_scenes["missing"]),
            str(broken_scenes["unknown"]), "--out", str(store), "--no-png"]
    proc = subprocess.run([sys.executable, "-c", "from sim2radar.cli import main; main()", *args],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    output = proc.stdout + proc.stderr
    assert proc.returncode == 1, output  # as the Prefect run: Failed
    assert "2 of 3 scenes failed" in output
    assert "Traceback" not in output and "Finished in state Failed" not in output, output
    assert "1 computed, 0 cached (skipped), 2 failed" in output
    assert "wall.ply: mesh file not found" in output
    rows = {r["scene_id"]: r for r in ArtifactStore(store).manifest("default").rows()}
    assert rows["plate"]["status"] == "ok"
    assert rows["missing_mesh"]["status"] == "failed"
    assert "wall.ply: mesh file not found" in rows["missing_mesh"]["error"]
    assert "unobtainium" in rows["unknown_material"]["error"]
