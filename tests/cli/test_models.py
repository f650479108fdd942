"""`sim2radar models check CONFIG`: every configured model file is loaded and runs one tiny input,
the VLM server is asked for its models; one line per backend, exit 0 / 1 / 2."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from sim2radar.camera import CameraIntrinsics
from sim2radar.cli import app
from tests.reconstruct._models import (
    SAM_INPUT,
    TINY_VOCAB,
    export_gdino_swin_like,
    export_moge_like,
    export_sam2_like,
)
from tests.reconstruct._vlm_server import VlmTestServer

runner = CliRunner()
CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "reconstruct"

#: The tiny MoGe-2 look-alike sees the plane 1/Z = 0.03 x_n + 0.12 y_n + 0.25: 2.7..5.5 m.
PLANE = (0.03, 0.12, 0.25)


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("models")
    export_moge_like(d / "moge.onnx", plane=PLANE, scale=2.0, shift=0.7,
                     ref_intrinsics=CameraIntrinsics.from_fov(48, 36, 60.0))
    export_sam2_like(d / "sam2.encoder.onnx", d / "sam2.decoder.onnx")
    export_gdino_swin_like(d / "groundingdino.onnx")  # dynamic H, W declared; runs at 800x1200
    (d / "vocab.txt").write_text("\n".join(TINY_VOCAB) + "\n")
    return d


def _config(model_dir, tmp_path, base_url: str, model: str = "test-vlm", **depth) -> str:
    """A production-style config next to the models, with paths relative to the YAML."""
    doc = {
        "depth": {"name": "moge", "options": {"model_path": "moge.onnx", **depth}},
        "segments": {"name": "sam2-gdino", "options": {
            "sam2_encoder_path": "sam2.encoder.onnx", "sam2_decoder_path": "sam2.decoder.onnx",
            "sam2_input_size": SAM_INPUT, "gdino_model_path": "groundingdino.onnx",
            "gdino_vocab_path": "vocab.txt"}},
        "materials": {"name": "vlm", "options": {
            "base_url": base_url, "model": model, "cache_path": str(tmp_path / "c.sqlite")}},
    }
    path = model_dir / f"check-{tmp_path.name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def _lines(res) -> list[str]:
    return res.output.strip().splitlines()


def test_all_ok_one_line_per_backend_exit_0(model_dir, tmp_path):
    with VlmTestServer("json") as srv:
        res = runner.invoke(app, ["models", "check", _config(model_dir, tmp_path, srv.base_url)],
                            env={"COLUMNS": "400"})
        assert srv.model_queries == 1 and srv.n_requests == 0  # a ping, no chat request
    assert res.exit_code == 0, res.output
    depth, segments, materials = _lines(res)
    assert depth.startswith("depth (moge): ok: moge.onnx ran a 96x72 image")
    lo, hi = map(float, re.search(r"metric depth ([\d.]+)-([\d.]+) m", depth).groups())
    assert 2.0 < lo < hi < 7.0  # the plane the graph was built to see
    assert segments.startswith("segments (sam2-gdino): ok: SAM2 (sam2.decoder.onnx) masks")
    assert "Grounding DINO (groundingdino.onnx) ran at 800x1200 (input_hw)" in segments
    assert materials == f"materials (vlm): ok: the server at {srv.base_url} serves 'test-vlm'"


def test_missing_model_file_and_wrong_model_name_exit_1(model_dir, tmp_path):
    with VlmTestServer("json", served_models=("/models/internvl",)) as srv:
        cfg = _config(model_dir, tmp_path, srv.base_url, model="OpenGVLab/InternVL2_5-8B",
                      model_path="moge-2-vitl-normal.onnx")
        res = runner.invoke(app, ["models", "check", cfg], env={"COLUMNS": "400"})
    assert res.exit_code == 1, res.output
    depth, segments, materials = _lines(res)
    assert depth.startswith("depth (moge): FAILED: ")
    assert "moge-2-vitl-normal.onnx not found" in depth and "Plugging in real models" in depth
    assert segments.startswith("segments (sam2-gdino): ok: ")
    assert materials == (
        f"materials (vlm): FAILED: the server at {srv.base_url} serves ['/models/internvl'], "
        "not 'OpenGVLab/InternVL2_5-8B': set materials.options.model to one of them, or start "
        "vLLM with --served-model-name OpenGVLab/InternVL2_5-8B (LMDeploy: --model-name "
        "OpenGVLab/InternVL2_5-8B)")


def test_a_wrong_grounding_dino_size_and_a_down_server_are_named(model_dir, tmp_path):
    srv = VlmTestServer("json")
    url = srv.base_url
    srv.close()  # nothing listens there any more
    cfg = yaml.safe_load(Path(_config(model_dir, tmp_path, url)).read_text())
    cfg["segments"]["options"]["gdino_input_hw"] = [480, 640]
    path = model_dir / f"wrong-hw-{tmp_path.name}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    res = runner.invoke(app, ["models", "check", str(path)], env={"COLUMNS": "400"})
    assert res.exit_code == 1, res.output
    _, segments, materials = _lines(res)
    assert segments.startswith("segments (sam2-gdino): FAILED: Grounding DINO: ")
    assert "480x640" in segments and "Swin" in segments and "gdino_input_hw" in segments
    assert materials.startswith("materials (vlm): FAILED: cannot reach the VLM server at ")


@pytest.mark.parametrize("name", ["builtin", "oracle"])
def test_built_in_backends_need_no_model_file(name):
    res = runner.invoke(app, ["models", "check", str(CONFIGS / f"{name}.yaml")])
    assert res.exit_code == 0, res.output
    assert all(line.endswith(": ok (built-in, no model file)") for line in _lines(res))
    assert len(_lines(res)) == 3


def test_a_bad_config_file_is_one_line_exit_2(tmp_path):
    missing = tmp_path / "nope.yaml"
    res = runner.invoke(app, ["models", "check", str(missing)])
    assert res.exit_code == 2 and len(_lines(res)) == 1 and "not found" in res.output
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"depth": {"name": "moge", "option": {}}}))
    res = runner.invoke(app, ["models", "check", str(bad)])
    assert res.exit_code == 2 and str(bad) in res.output and len(_lines(res)) == 1
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text(yaml.safe_dump({"segments": {"name": "sam3"}}))
    res = runner.invoke(app, ["models", "check", str(unknown)])
    assert res.exit_code == 2 and len(_lines(res)) == 1
    assert "unknown segmentation backend 'sam3'" in res.output and "sam2-gdino" in res.output
