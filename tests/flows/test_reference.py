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
    # an imaging radar's density: far above the ray-traced sim's ~100 points per frame
    assert ref["points_per_frame"] > 300
    meta = json.loads((export / "dataset.json").read_text())
    assert meta["domain"] == "proxy-real (reference radar simulation)"
    ds = OpenPCDetDataset(export)
    worlds = {}
    for split in ("train", "val", "test"):
        for fid in ds.split_ids(split):
            world = fid.rsplit("_f", 1)[0]
            assert worlds.setdefault(world, split) == split      # no world in two splits
            assert int(world.split("_")[1]) >= 100_000          # disjoint from seeds 0..
    assert len(worlds) == 3
    pts = np.load(next((export / "points").glob("*.npy")))
    assert pts.dtype == np.float32 and pts.shape[1] == 5         # x y z intensity doppler
    assert np.all(pts[:, 4] == 0.0)                              # static scenes
    again = runner.invoke(app, args)
    assert again.exit_code == 0 and "0 computed" in again.output


def test_reference_cli_refuses_a_bad_preset_with_exit_2(tmp_path):
    result = runner.invoke(app, ["reference", "--worlds", "3", "--radar", "no-such-radar",
                                 "--out", str(tmp_path / "s"), "--no-prefect"])
    assert result.exit_code == 2 and "no-such-radar" in result.output
