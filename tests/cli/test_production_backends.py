"""`sim2radar generate --captures` end to end through the production backends (issue 25's "done
when"): a 640x480 capture folder runs through MoGe-2 (ONNX), SAM2 + a Grounding DINO graph that
declares dynamic H, W but only runs at 800x1200 (a public Swin export), and a VLM behind a
loopback OpenAI-compatible server; forcing the graph to 480x640 fails the scene with the one-line
error naming the Swin export limit, recorded in the manifest, without a traceback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from sim2radar.camera import CameraIntrinsics
from sim2radar.cli import app
from sim2radar.storage import ArtifactStore
from tests.reconstruct._models import (
    SAM_INPUT,
    TINY_VOCAB,
    export_gdino_swin_like,
    export_moge_like,
    export_sam2_like,
)
from tests.reconstruct._vlm_server import VlmTestServer

REPO = Path(__file__).resolve().parents[2]

SCENE = "scene_004"
#: A saturated red door painted into the 640 x 480 capture [px]: rows 120..300, columns
#: 200..360 (edges on the tiny SAM2's 4 px cells of its 64 x 64 input: 30 px down, 40 px
#: across); the only pixels the tiny Grounding DINO's "door" query measures, since the rest of
#: the picture is dimmed below its threshold.
DOOR_RC = (120, 300, 200, 360)


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    root = tmp_path_factory.mktemp("caps640")
    res = CliRunner().invoke(app, ["worlds", "captures", "--out", str(root), "--worlds", "1",
                                   "--first-seed", "4", "--width", "640", "--height", "480",
                                   "--spp", "2"])
    assert res.exit_code == 0, res.output
    png = root / SCENE / "rgb.png"
    bgr = cv2.imread(str(png), cv2.IMREAD_COLOR)
    assert bgr.shape == (480, 640, 3)
    bgr = (bgr * 0.5).astype(np.uint8)  # red channel < 128: below the detector's threshold
    r0, r1, c0, c1 = DOOR_RC
    bgr[r0:r1, c0:c1] = (0, 0, 255)
    assert cv2.imwrite(str(png), bgr)
    return root


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("models640")
    export_moge_like(d / "moge.onnx", plane=(0.03, 0.12, 0.25), scale=2.0, shift=0.7,
                     ref_intrinsics=CameraIntrinsics.from_fov(48, 36, 60.0))
    export_sam2_like(d / "sam2.encoder.onnx", d / "sam2.decoder.onnx")
    export_gdino_swin_like(d / "groundingdino.onnx")  # dynamic H, W declared; runs at 800x1200
    (d / "vocab.txt").write_text("\n".join(TINY_VOCAB) + "\n")
    return d


def _run(captures, model_dir, tmp_path, base_url: str, **segments):
    """`generate --captures` with a production-style reconstruction YAML next to the models
    (paths relative to it), two radar poses; returns (exit status, the output, manifest rows by
    id, export folder)."""
    rec = {
        "depth": {"name": "moge", "options": {"model_path": "moge.onnx"}},
        "segments": {"name": "sam2-gdino", "options": {
            "sam2_encoder_path": "sam2.encoder.onnx", "sam2_decoder_path": "sam2.decoder.onnx",
            "sam2_input_size": SAM_INPUT, "gdino_model_path": "groundingdino.onnx",
            "gdino_vocab_path": "vocab.txt", **segments}},
        "materials": {"name": "vlm", "options": {
            "base_url": base_url, "model": "test-vlm", "cache_path": str(tmp_path / "vlm.sqlite"),
            "on_error": "unknown"}},
    }
    cfg = model_dir / f"rec-{tmp_path.name}.yaml"
    cfg.write_text(yaml.safe_dump(rec))
    gen = tmp_path / "gen.yaml"
    gen.write_text("poses: {frames: 2, forward_m: [0.0, 1.0]}\n")
    store, export = tmp_path / "store", tmp_path / "opcd"
    # a real process: its whole stdout + stderr is what a user sees (in-process, a second CLI
    # run would log through Prefect's console handler still bound to the first run's stream)
    res = subprocess.run(
        [sys.executable, "-c", "from sim2radar.cli import main; main()", "generate",
         "--captures", str(captures), "--no-prefect", "--no-png", "--config", str(gen),
         "--reconstruction", str(cfg), "--out", str(store), "--export-openpcdet", str(export),
         "--json", str(tmp_path / "summary.json")],
        cwd=REPO, env={**os.environ, "COLUMNS": "400"}, capture_output=True, text=True,
        timeout=300)
    rows = {r["scene_id"]: r for r in ArtifactStore(store).manifest("captures").rows()}
    return res.returncode, res.stdout + res.stderr, rows, export


def test_a_640x480_capture_runs_through_an_800x1200_grounding_dino(captures, model_dir,
                                                                    tmp_path):
    from sim2radar.storage.reconstruction import segments_from_table

    with VlmTestServer("json") as srv:
        code, output, rows, export = _run(captures, model_dir, tmp_path, srv.base_url)
        n_chat = srv.n_requests
    assert code == 0, output
    assert "Traceback" not in output and "error" not in output.lower(), output
    frames = [f"{SCENE}_f000", f"{SCENE}_f001"]
    assert sorted(rows) == sorted([SCENE, *frames])
    assert {k: (r["status"], r["error"]) for k, r in rows.items()} == \
        {k: ("ok", "") for k in rows}
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 0}
    assert summary["frame_counts"] == {"ok": 2, "skipped": 0, "failed": 0}
    assert sorted(p.stem for p in (export / "points").glob("*.npy")) == frames
    assert (export / "ImageSets" / "train.txt").read_text().split() == frames
    for f in frames:
        pts = np.load(export / "points" / f"{f}.npy")
        assert pts.shape[1] == 4 and len(pts) > 0

    # Grounding DINO ran at the size the graph was exported at, its "door" box came back to the
    # capture's pixels, and labelled SAM2's mask of the painted door
    st = ArtifactStore(tmp_path / "store")
    keys = rows[SCENE]["artifacts"]
    seg, _ = segments_from_table(st.read("segmentations", keys["segmentations"]))
    assert seg.segment_id.shape == (480, 640)
    assert seg.info["gdino_input_hw"] == [800, 1200]
    (label, score, *box), = seg.info["detections"]
    r0, r1, c0, c1 = DOOR_RC
    assert label == "door" and score > 0.99
    np.testing.assert_allclose(box, [c0, r0, c1, r1], atol=1.0)
    door = seg.segment_id == seg.labels.index("door")
    truth = np.zeros((480, 640), bool)
    truth[r0:r1, c0:c1] = True
    assert (door & truth).sum() / (door | truth).sum() > 0.9
    # the VLM answered for every segment (the loopback server: a door is metal)
    assert n_chat == len(seg.labels) > 1
    mats = st.read("material_labels", keys["material_labels"]).to_pylist()[0]
    assert mats["materials"][seg.labels.index("door")] == "metal"
    assert mats["fallbacks"] == []


def test_forcing_480x640_fails_the_scene_with_the_swin_line(captures, model_dir, tmp_path):
    with VlmTestServer("json") as srv:
        code, output, rows, export = _run(captures, model_dir, tmp_path, srv.base_url,
                                          gdino_input_hw=[480, 640])
        assert srv.n_requests == 0  # segmentation failed first: no segment reached the VLM
    assert code == 1, output  # the failed scene is recorded, and the exit status says so
    assert "Traceback" not in output, output
    # the scene fails before any radar frame exists: no frame row, none ok
    assert list(rows) == [SCENE]
    row = rows[SCENE]
    assert row["status"] == "failed"
    err = row["error"]
    assert "\n" not in err
    assert err.startswith("[segments] ModelSignatureError: Grounding DINO: groundingdino.onnx "
                          "does not run at 480x640: a Swin-backbone export fixes"), err
    assert "800x1200" in err and "gdino_input_hw" in err and "Reshape" in err
    assert f"✗ {SCENE}: [segments] ModelSignatureError: Grounding DINO" in output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"] == {"ok": 0, "skipped": 0, "failed": 1}
    # the export is an empty dataset, said so, rather than a crash
    assert list((export / "points").glob("*.npy")) == []
    assert (export / "ImageSets" / "train.txt").read_text() == ""
    assert "warning: no frame to export" in output
