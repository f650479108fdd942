"""``sim2radar worlds`` commands."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.storage import ArtifactStore

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "worlds"


def test_shipped_configs_load():
    from sim2radar.worlds import RigConfig, WorldConfig, load_worlds_config

    world, rig = load_worlds_config(CONFIGS / "default.yaml")
    assert world == WorldConfig() and rig == RigConfig()
    load_worlds_config(CONFIGS / "small.yaml")


def test_preview_writes_a_contact_sheet(tmp_path):
    out = tmp_path / "sheet.png"
    res = CliRunner().invoke(app, ["worlds", "preview", "--seed", "4", "--out", str(out),
                                   "--width", "64", "--height", "48", "--spp", "2"])
    assert res.exit_code == 0, res.output
    assert "doors" in res.output
    import cv2

    img = cv2.imread(str(out))
    assert img is not None and img.shape[0] > 400 and img.std() > 10


def test_bad_config_exits_with_the_field(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("world:\n  corridor_width_m: [3, 1]\n")
    res = CliRunner().invoke(app, ["worlds", "preview", "--config", str(bad),
                                   "--out", str(tmp_path / "x.png")])
    assert res.exit_code == 2
    assert "corridor_width_m" in res.output


def test_generate_without_prefect(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("world:\n  corridor_length_m: [10, 11]\nrig:\n  width: 48\n  height: 32\n"
                   "  spp: 2\n  lidar_azimuth_step_deg: 4.0\n")
    store = tmp_path / "store"
    args = ["worlds", "generate", "--worlds", "1", "--frames", "1", "--out", str(store),
            "--config", str(cfg), "--no-prefect", "--dataset", "cli"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert '"ok": 1' in res.output
    rows = ArtifactStore(store).manifest("cli").rows()
    assert rows[0]["status"] == "ok" and set(rows[0]["artifacts"]) >= {"world_frames"}
    res = CliRunner().invoke(app, args)
    assert '"skipped": 1' in res.output
    assert np.isfinite(rows[0]["timings_s"]["total"])
