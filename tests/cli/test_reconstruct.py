"""`sim2radar reconstruct`: every frame is a manifest row (ok / skipped / failed) while the
others finish; bad intrinsics and unwritable stores are one line, exit 2."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.reconstruct.synthetic import corridor_frame
from sim2radar.storage import ArtifactStore

runner = CliRunner()


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A corridor image + LiDAR, a broken 'image' with the same LiDAR, and their intrinsics."""
    root = tmp_path_factory.mktemp("frames")
    frame = corridor_frame(160, 120, seed=1)
    cv2.imwrite(str(root / "corridor.png"), frame.rgb[..., ::-1])
    (root / "broken.png").write_bytes(b"not an image")
    np.save(root / "lidar.npy", frame.lidar_points)
    (root / "K.yaml").write_text(yaml.safe_dump(frame.intrinsics.to_dict()))
    return root


def _args(root, store, intrinsics="K.yaml"):
    return ["reconstruct", str(root / "corridor.png"), str(root / "broken.png"),
            "--intrinsics", str(root / intrinsics), "--lidar", str(root / "lidar.npy"),
            "--lidar", str(root / "lidar.npy"), "--out", str(store), "--dataset", "lab"]


def test_every_frame_is_recorded_in_the_manifest(inputs, tmp_path):
    store = tmp_path / "out" / "store"
    first = runner.invoke(app, _args(inputs, store), env={"COLUMNS": "400"})
    assert first.exit_code == 1, first.output  # a frame failed; the other finished
    assert "Traceback" not in first.output
    assert "broken: failed: ReconstructionInputError" in first.output
    assert "1 computed, 0 cached (skipped), 1 failed" in first.output
    rows = {r["scene_id"]: r for r in ArtifactStore(store).manifest("lab").rows()}
    assert rows["corridor"]["status"] == "ok"
    assert set(rows["corridor"]["artifacts"]) == {"scene_meshes", "reconstruction"}
    assert rows["broken"]["status"] == "failed"
    assert "broken.png: not a readable image" in rows["broken"]["error"]
    assert (tmp_path / "out" / "sheets" / "corridor.png").is_file()
    # a second run recomputes nothing that is cached and records that too
    again = runner.invoke(app, _args(inputs, store), env={"COLUMNS": "400"})
    assert "corridor: skipped (cached)" in again.output, again.output
    rows2 = {r["scene_id"]: r for r in ArtifactStore(store).manifest("lab").rows()}
    assert rows2["corridor"]["status"] == "skipped" and rows2["corridor"]["attempts"] == 2
    assert rows2["corridor"]["artifacts"] == rows["corridor"]["artifacts"]
    assert rows2["broken"]["status"] == "failed"


def test_bad_intrinsics_and_unwritable_store_are_one_line(inputs, tmp_path, unwritable_dir):
    k = yaml.safe_load((inputs / "K.yaml").read_text())
    (tmp_path / "K_bad.yaml").write_text(yaml.safe_dump({**k, "cx": [120.0]}))
    args = _args(inputs, tmp_path / "store")
    args[args.index("--intrinsics") + 1] = str(tmp_path / "K_bad.yaml")
    for cmd, expect in (
            (args, "error: --intrinsics: "
                   f"{tmp_path / 'K_bad.yaml'}: cx: must be a number [px], got [120.0]; "
                   "write e.g. 'cx: 320.0'"),
            (_args(inputs, unwritable_dir / "store"), "error: --out: store ")):
        res = runner.invoke(app, cmd, env={"COLUMNS": "400"})
        assert res.exit_code == 2, res.output
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(expect), res.output


def test_a_vlm_model_name_the_server_does_not_serve_stops_the_run_before_any_image(
        inputs, tmp_path):
    """With ``on_error: unknown``, a misnamed model used to label every segment ``unknown``
    (HTTP 404, not retried, then the fallback); now the command asks the server once before any
    image, and stops with exit 2 and one line naming the served names and the fix. Nothing is
    written and no segment is sent."""
    from tests.reconstruct._vlm_server import VlmTestServer

    with VlmTestServer("json", served_models=("/models/internvl",)) as srv:
        cfg = tmp_path / "vlm.yaml"
        cfg.write_text(yaml.safe_dump({"materials": {"name": "vlm", "options": {
            "base_url": srv.base_url, "model": "OpenGVLab/InternVL2_5-8B",
            "on_error": "unknown"}}}))
        res = runner.invoke(app, ["reconstruct", str(inputs / "corridor.png"), "--intrinsics",
                                  str(inputs / "K.yaml"), "--lidar", str(inputs / "lidar.npy"),
                                  "--config", str(cfg), "--out", str(tmp_path / "store")],
                            env={"COLUMNS": "400"})
        assert srv.n_requests == 0 and srv.model_queries == 1
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        f"error: materials (vlm): the server at {srv.base_url} serves ['/models/internvl'], "
        "not 'OpenGVLab/InternVL2_5-8B'") and "--served-model-name" in lines[0], res.output
    assert not (tmp_path / "store" / "manifests").exists()
