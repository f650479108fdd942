"""`sim2radar reference`: the proxy-real dataset from one command — reference-radar frames of
worlds disjoint from the sim domain, split by world, labelled as a proxy, cached."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.datasets import OpenPCDetDataset

runner = CliRunner()


def test_reference_cli_builds_a_labelled_proxy_dataset_split_by_world(tmp_path):
    store, export = tmp_path / "store", tmp_path / "proxy_real"
    args = ["reference", "--worlds", "3", "--frames", "2", "--out", str(store),
            "--export-openpcdet", str(export), "--no-png", "--no-prefect",
            "--json", str(tmp_path / "s.json")]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "proxy-real (reference radar simulation)" in result.output
    summary = json.loads((tmp_path / "s.json").read_text())
    ref = summary["geometry"]["ground_truth"]
    assert summary["counts"] == {"ok": 3, "skipped": 0, "failed": 0} and ref["frames"] == 6
    assert ref["points_per_frame"] > 0       # the density is a result, not a target
    meta = json.loads((export / "dataset.json").read_text())
    assert meta["domain"] == "proxy-real (reference radar simulation)"
    assert meta["rig_motion"]["speed_mps"] == [0.5, 1.5]
    assert meta["radar_height_m"] == 1.05 and 0.03 < meta["range_resolution_m"] < 0.04
    ds = OpenPCDetDataset(export)
    worlds = {}
    for split in ("train", "val", "test"):
        for fid in ds.split_ids(split):
            world = fid.rsplit("_f", 1)[0]
            assert worlds.setdefault(world, split) == split      # no world in two splits
            assert int(world.split("_")[1]) >= 100_000          # disjoint from seeds 0..
    assert len(worlds) == 3
    for path in (export / "points").glob("*.npy"):
        pts = np.load(path)
        assert pts.dtype == np.float32 and pts.shape[1] == 5     # x y z intensity doppler
        # the rig walks forward at 0.5-1.5 m/s through a static scene: every point of the
        # scene moves, towards the radar, within the Doppler axis (+-1.55 m/s: the unwindowed
        # Doppler FFT's sidelobes of the fastest returns reach its edge); the radar's own
        # TX->RX leakage (first range bins kept, ~0.4 m) stays at zero Doppler
        scene = np.linalg.norm(pts[:, :3], axis=1) > 0.5
        assert np.all(pts[scene, 4] < 0.0) and np.all(pts[:, 4] > -1.56)
    again = runner.invoke(app, args)
    assert again.exit_code == 0 and "0 computed" in again.output
    still = runner.invoke(app, [*args[:6], str(tmp_path / "still"), "--speed", "0", "0",
                                "--no-png", "--no-prefect", "--worlds", "1"])
    assert still.exit_code == 0, still.output
    for path in (tmp_path / "still" / "points").glob("*.npy"):
        assert np.all(np.load(path)[:, 4] == 0.0)               # standing still: no Doppler


def test_reference_cli_refuses_a_bad_preset_with_exit_2(tmp_path):
    result = runner.invoke(app, ["reference", "--worlds", "3", "--radar", "no-such-radar",
                                 "--out", str(tmp_path / "s"), "--no-prefect"])
    assert result.exit_code == 2 and "no-such-radar" in result.output


def _clouds(points_dir):
    return {p.name: np.load(p) for p in sorted(points_dir.glob("*.npy"))}


def test_two_worlds_at_once_give_the_frames_of_one_at_a_time(prefect_server, tmp_path):
    """The demo's data stages run two worlds at once on worker threads (``--workers 2``): the
    simulated domain (render, reconstruction, the ray tracer on both geometries) and the
    reference radar give the frames, bit for bit, that one world at a time gives."""
    jobs = {"generate": ["generate", "--worlds", "2", "--frames", "1", "--geometry", "both",
                         "--width", "160", "--height", "120", "--spp", "4"],
            "reference": ["reference", "--worlds", "2", "--frames", "1"]}
    for job, args in jobs.items():
        frames = {}
        for how, extra in (("alone", ["--no-prefect"]), ("threads", ["--workers", "2"])):
            out = tmp_path / job / how
            result = runner.invoke(app, [*args, "--out", str(out / "store"), "--no-png",
                                         "--export-openpcdet", str(out / "export"), *extra])
            assert result.exit_code == 0, result.output
            exported = sorted(p for p in (out / "export").rglob("points") if p.is_dir())
            frames[how] = {str(p.relative_to(out)): _clouds(p) for p in exported}
        alone, threads = frames["alone"], frames["threads"]
        assert alone.keys() == threads.keys() and sum(len(v) for v in alone.values()) >= 2
        for folder, clouds in alone.items():
            assert clouds.keys() == threads[folder].keys()
            assert all(np.array_equal(clouds[n], threads[folder][n]) for n in clouds), job
