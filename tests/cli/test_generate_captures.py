"""`sim2radar generate --captures`: a capture folder to an OpenPCDet dataset in one command;
procedural-only options and bad folders are one line, exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from sim2radar.cli import app


@pytest.fixture(scope="module")
def one_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("caps")
    res = CliRunner().invoke(app, ["worlds", "captures", "--out", str(root), "--worlds", "1",
                                   "--first-seed", "4", "--width", "160", "--height", "120",
                                   "--spp", "4"])
    assert res.exit_code == 0, res.output
    return root


@pytest.mark.parametrize("extra, message", [
    (["--worlds", "2"], "['--worlds'] describe procedural worlds"),
    (["--geometry", "both"], "['--geometry'] describe procedural worlds"),
])
def test_procedural_options_are_refused(one_scene, tmp_path, extra, message):
    res = CliRunner().invoke(app, ["generate", "--captures", str(one_scene), "--no-prefect",
                                   "--out", str(tmp_path / "store"), *extra],
                             env={"COLUMNS": "400"})
    assert res.exit_code == 2 and message in res.output, res.output
    assert "Traceback" not in res.output


def test_missing_capture_folder_is_one_line(tmp_path):
    res = CliRunner().invoke(app, ["generate", "--captures", str(tmp_path / "none"),
                                   "--no-prefect", "--out", str(tmp_path / "store")],
                             env={"COLUMNS": "400"})
    assert res.exit_code == 2 and "capture folder not found" in res.output, res.output


def test_a_misnamed_vlm_model_stops_generate_before_any_work(one_scene, tmp_path):
    """Both entry points that reconstruct ask the VLM server first: `generate --captures` and
    procedural `generate` exit 2 with one line naming the served models, before any frame."""
    import yaml

    from tests.reconstruct._vlm_server import VlmTestServer

    with VlmTestServer("json", served_models=("/models/internvl",)) as srv:
        cfg = tmp_path / "vlm.yaml"
        cfg.write_text(yaml.safe_dump({"materials": {"name": "vlm", "options": {
            "base_url": srv.base_url, "model": "OpenGVLab/InternVL2_5-8B",
            "on_error": "unknown"}}}))
        for args in (["--captures", str(one_scene)], ["--worlds", "1", "--frames", "1"]):
            res = CliRunner().invoke(app, ["generate", *args, "--no-prefect", "--reconstruction",
                                           str(cfg), "--out", str(tmp_path / "store")],
                                     env={"COLUMNS": "400"})
            assert res.exit_code == 2, res.output
            assert "error: materials (vlm): the server at" in res.output
            assert "not 'OpenGVLab/InternVL2_5-8B'" in res.output
            assert "Traceback" not in res.output
        assert srv.n_requests == 0 and srv.model_queries == 2
    assert not (tmp_path / "store" / "manifests").exists()


def test_capture_folder_to_openpcdet_in_one_command(one_scene, tmp_path):
    cfg = tmp_path / "gen.yaml"
    cfg.write_text("poses: {frames: 3, forward_m: [0.0, 1.5]}\nseed: 2\n")
    export = tmp_path / "opcd"
    res = CliRunner().invoke(app, ["generate", "--captures", str(one_scene), "--no-prefect",
                                   "--config", str(cfg), "--out", str(tmp_path / "store"),
                                   "--export-openpcdet", str(export), "--json",
                                   str(tmp_path / "summary.json")], env={"COLUMNS": "400"})
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 0}
    assert summary["frame_counts"]["ok"] == 3 and summary["unit"] == "scenes"
    ids = sorted(p.stem for p in (export / "points").glob("*.npy"))
    assert ids == ["scene_004_f000", "scene_004_f001", "scene_004_f002"]
    assert np.load(export / "points" / f"{ids[0]}.npy").shape[1] == 4
    assert "seconds per step" in res.output and "GT doors" not in res.output
    assert (tmp_path / "bev" / "scene_004_rec.png").is_file()
    # one scene cannot fill val and test: said, not silent
    assert "warning:" in res.output and "are empty" in res.output
    meta = json.loads((export / "dataset.json").read_text())
    assert any("['val', 'test'] are empty" in w for w in meta["warnings"])
