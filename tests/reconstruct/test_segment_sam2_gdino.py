"""Tests for the ``sam2-gdino`` segmentation backend with tiny test-built ONNX models."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct._onnx import ModelSignatureError
from sim2radar.reconstruct.segment_sam2_gdino import (
    GDINO_EXPORT_HW,
    Detections,
    GroundingDino,
    GroundingDinoConfig,
    Sam2GdinoSegments,
    WordPieceTokenizer,
    match_masks_to_detections,
    text_masks,
)
from sim2radar.reconstruct.types import (
    SEGMENT_BACKENDS,
    DepthResult,
    FrameInput,
    ReconstructionInputError,
)
from tests.reconstruct._models import (
    SAM_INPUT,
    SEG_HW,
    TINY_VOCAB,
    export_gdino_like,
    export_gdino_swin_like,
    export_sam2_like,
    render_seg_scene,
    seg_scene_boxes,
)


def _queries(skip=()):
    b = seg_scene_boxes()
    q = [("door", 0, b["door"]), ("wall", 0, b["wall"]), ("floor", 0, b["floor"]),
         ("ceiling", 0, b["ceiling"]), ("window", 0, b["window"]),
         # "fire extinguisher" = fire ex ##ting ##uish ##er: fires on the 4th token of its phrase
         ("##uish", 3, b["fire_extinguisher"]),
         # "handrail" = hand ##rail: a detection on the floor edge that matches no mask
         ("##rail", 1, (0.5, 0.95, 0.3, 0.04)),
         ("cat", 0, (0.5, 0.5, 0.1, 0.1))]  # "cat" is not in the prompt: never detected
    return [x for x in q if x[0] not in skip]


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp("sam2gdino")
    enc, dec = export_sam2_like(d / "enc.onnx", d / "dec.onnx")
    _, dec_no_orig = export_sam2_like(d / "enc2.onnx", d / "dec2.onnx", with_orig_size=False)
    vocab = d / "vocab.txt"
    vocab.write_text("\n".join(TINY_VOCAB) + "\n")
    return {
        "enc": enc, "dec": dec, "dec_no_orig": dec_no_orig, "vocab": vocab,
        "gd": export_gdino_like(d / "gd.onnx", _queries()),
        "gd_no_window": export_gdino_like(d / "gd2.onnx", _queries(skip=("window",))),
    }


@pytest.fixture(scope="module")
def frame():
    rgb, _ = render_seg_scene()
    return FrameInput(rgb, CameraIntrinsics.from_fov(SEG_HW[1], SEG_HW[0], 60), name="seg")


def _backend(models, dec="dec", gd="gd", **kw):
    sam2 = dict(encoder_path=str(models["enc"]), decoder_path=str(models[dec]),
                input_size=SAM_INPUT, points_per_side=16, points_per_batch=48, min_area_px=4)
    sam2.update(kw.pop("sam2", {}))
    gdino = dict(model_path=str(models[gd]), vocab_path=str(models["vocab"]))
    return Sam2GdinoSegments(sam2=sam2, gdino=gdino, **kw)


def _depth():
    return DepthResult(np.ones(SEG_HW, np.float32))


def test_registered():
    assert SEGMENT_BACKENDS.get("sam2-gdino") is Sam2GdinoSegments


def test_wordpiece_and_grounding_dino_text_masks(tmp_path):
    tok = WordPieceTokenizer({t: i for i, t in enumerate(TINY_VOCAB)})
    assert tok.basic_tokens("Fire Extinguisher, door.") == ["fire", "extinguisher", ",",
                                                             "door", "."]
    assert tok.wordpieces("extinguisher") == ["ex", "##ting", "##uish", "##er"]
    assert tok.wordpieces("handrail") == ["hand", "##rail"]
    assert tok.wordpieces("sofa") == ["[UNK]"]
    ids, spans = tok.encode_phrases(["door", "fire extinguisher"])
    toks = [TINY_VOCAB[i] for i in ids]
    assert toks == ["[CLS]", "door", ".", "fire", "ex", "##ting", "##uish", "##er", ".", "[SEP]"]
    assert spans == [[1], [3, 4, 5, 6, 7]]
    att, pos = text_masks(ids, tok.special_ids())
    # Grounding DINO: position ids restart after each '.', phrases attend only to themselves.
    assert pos.tolist() == [0, 0, 1, 0, 1, 2, 3, 4, 5, 0]
    assert att[3, 7] and att[7, 8] and not att[1, 3] and not att[0, 1] and att[9, 9]
    # tokenizer.json form of the same vocabulary
    tj = tmp_path / "tokenizer.json"
    tj.write_text(json.dumps({"model": {"vocab": {t: i for i, t in enumerate(TINY_VOCAB)}}}))
    assert WordPieceTokenizer(tj).encode_phrases(["door"])[0].tolist() == [2, 8, 5, 3]


def test_masks_and_labels_of_the_synthetic_scene(models, frame):
    backend = _backend(models)
    seg = backend.segment(frame, _depth())
    _, truth = render_seg_scene()
    assert sorted(seg.labels) == sorted(truth)  # one segment per region, labelled correctly
    for i, label in enumerate(seg.labels):
        m = seg.segment_id == i
        iou = (m & truth[label]).sum() / (m | truth[label]).sum()
        assert iou > 0.95, (label, iou)
        assert seg.scores[i] > 0.99
    assert (seg.segment_id >= 0).all()
    dets = seg.detections
    assert "handrail" in dets.labels  # detected, but matched to no mask
    assert "handrail" not in seg.labels
    assert len(dets) == 7  # the decoy "cat" query never fires


def test_decoder_without_orig_im_size_input_and_flat_options(models, frame):
    backend = Sam2GdinoSegments(
        sam2_encoder_path=str(models["enc"]), sam2_decoder_path=str(models["dec_no_orig"]),
        sam2_input_size=SAM_INPUT, sam2_points_per_side=16, sam2_min_area_px=4,
        gdino_model_path=str(models["gd"]), gdino_vocab_path=str(models["vocab"]),
    )
    seg = backend.segment(frame, _depth())
    assert "fire_extinguisher" in seg.labels
    info = json.loads(json.dumps(seg.info))
    assert info["n_labelled"] == 6 and len(info["detections"]) == 7


def test_unmatched_masks_kept_as_unknown_or_dropped(models, frame):
    _, truth = render_seg_scene()
    kept = _backend(models, gd="gd_no_window").segment(frame, _depth())
    i = kept.labels.index("unknown")
    assert kept.scores[i] == 0
    assert ((kept.segment_id == i) == truth["window"]).all()
    dropped = _backend(models, gd="gd_no_window", keep_unmatched=False).segment(frame, _depth())
    assert "unknown" not in dropped.labels and len(dropped.labels) == 5
    assert (dropped.segment_id[truth["window"]] == -1).all()
    assert dropped.segment_id.max() == 4


def test_match_by_iou_prefers_the_tight_box():
    seg = np.full((10, 10), -1, np.int32)
    seg[2:8, 2:5] = 0
    seg[:, 6:] = 1
    dets = Detections(np.array([[0, 0, 10, 10], [2, 2, 5, 8]], np.float32),
                      ("wall", "door"), np.array([0.9, 0.6], np.float32))
    labels, scores, ious = match_masks_to_detections(seg, dets, 0.2)
    assert labels == ["door", "wall"]
    assert scores.tolist() == pytest.approx([0.6, 0.9])
    assert ious[0] == pytest.approx(1.0)


def test_errors_are_clear(models, frame, tmp_path):
    with pytest.raises(ValueError, match="needs options sam2"):
        Sam2GdinoSegments()
    with pytest.raises(ValueError, match="unknown option 'encoder'"):
        Sam2GdinoSegments(encoder="x.onnx")
    with pytest.raises(FileNotFoundError, match="SAM2 encoder"):
        _backend(models, sam2={"encoder_path": str(tmp_path / "none.onnx")})
    with pytest.raises(ModelSignatureError, match="missing outputs"):
        _backend(models, sam2={"decoder_outputs": ("low_res_masks", "iou_predictions")})
    with pytest.raises(ValueError, match="known options"):
        _backend(models, sam2={"points": 3})
    bad_vocab = tmp_path / "v.txt"
    bad_vocab.write_text("door\nwall\n")
    with pytest.raises(ValueError, match="lacks the token"):
        Sam2GdinoSegments(
            sam2=dict(encoder_path=str(models["enc"]), decoder_path=str(models["dec"])),
            gdino=dict(model_path=str(models["gd"]), vocab_path=str(bad_vocab)),
        )
    with pytest.raises(ReconstructionInputError, match="no masks"):
        _backend(models, sam2={"pred_iou_thresh": 0.99}).segment(frame, _depth())


# --- Grounding DINO input size: a Swin export runs only at the size it was traced at ---------

#: A 640 x 480 capture with a saturated red door [px]: rows 120..300, columns 200..360.
DOOR_RC = (120, 300, 200, 360)


def _red_door_frame() -> FrameInput:
    rgb = np.full((480, 640, 3), 40, np.uint8)
    r0, r1, c0, c1 = DOOR_RC
    rgb[r0:r1, c0:c1] = (255, 0, 0)
    return FrameInput(rgb, CameraIntrinsics.from_fov(640, 480, 65), name="cam640x480")


@pytest.fixture(scope="module")
def swin_gd(tmp_path_factory):
    return export_gdino_swin_like(tmp_path_factory.mktemp("swin") / "gd_swin.onnx")


def test_dynamic_declared_swin_graph_runs_a_640x480_frame_at_800x1200(models, swin_gd):
    gd = GroundingDino(GroundingDinoConfig(model_path=str(swin_gd),
                                           vocab_path=str(models["vocab"])))
    h, w = gd.model.input_shape("img")[2:]
    assert not isinstance(h, int) and not isinstance(w, int)  # the graph says "any size"
    assert gd.input_hw == GDINO_EXPORT_HW == (800, 1200)
    frame = _red_door_frame()
    dets = gd.detect(frame.rgb)
    assert dets.labels == ("door",)
    # the graph measured the red patch in its 800 x 1200 input; back in the frame's pixels it
    # is the patch itself (a plain resize keeps normalised coordinates), to a pixel
    r0, r1, c0, c1 = DOOR_RC
    np.testing.assert_allclose(dets.boxes[0], [c0, r0, c1, r1], atol=1.0)


def test_the_whole_backend_labels_the_door_of_a_640x480_frame(models, swin_gd):
    backend = Sam2GdinoSegments(
        sam2=dict(encoder_path=str(models["enc"]), decoder_path=str(models["dec"]),
                  input_size=SAM_INPUT, points_per_side=16, min_area_px=4),
        gdino=dict(model_path=str(swin_gd), vocab_path=str(models["vocab"])))
    frame = _red_door_frame()
    seg = backend.segment(frame, DepthResult(np.ones(frame.shape, np.float32)))
    assert seg.info["gdino_input_hw"] == [800, 1200]
    truth = np.zeros(frame.shape, bool)
    r0, r1, c0, c1 = DOOR_RC
    truth[r0:r1, c0:c1] = True
    door = seg.segment_id == seg.labels.index("door")
    assert (door & truth).sum() / (door | truth).sum() > 0.9


def test_a_wrong_input_hw_is_one_line_naming_swin_and_the_option(models, swin_gd):
    backend = Sam2GdinoSegments(  # flat option, a YAML list
        sam2_encoder_path=str(models["enc"]), sam2_decoder_path=str(models["dec"]),
        sam2_input_size=SAM_INPUT, sam2_points_per_side=16, sam2_min_area_px=4,
        gdino_model_path=str(swin_gd), gdino_vocab_path=str(models["vocab"]),
        gdino_input_hw=[480, 640])
    assert backend.gdino.input_hw == (480, 640)
    frame = _red_door_frame()
    with pytest.raises(ModelSignatureError) as err:
        backend.segment(frame, DepthResult(np.ones(frame.shape, np.float32)))
    msg = str(err.value)
    assert "\n" not in msg
    assert "480x640" in msg and "Swin" in msg and "gdino_input_hw" in msg and "800x1200" in msg
    assert "Reshape" in msg  # what onnxruntime said, condensed


def test_input_hw_against_a_fixed_graph_and_bad_values(models):
    # the tiny graph of the other tests is fixed at 64 x 64: that is its size unless told
    gd = GroundingDino(GroundingDinoConfig(model_path=str(models["gd"]),
                                           vocab_path=str(models["vocab"])))
    assert gd.input_hw == SEG_HW
    with pytest.raises(ModelSignatureError, match=r"fixed 64x64 image.*input_hw is \[32, 48\]"):
        GroundingDino(GroundingDinoConfig(model_path=str(models["gd"]),
                                          vocab_path=str(models["vocab"]), input_hw=(32, 48)))
    with pytest.raises(ValueError, match="input_hw must be"):
        GroundingDinoConfig(model_path="x", vocab_path="y", input_hw=(800,))


# --- SAM2 exported by onnxruntime's own exporter: other names, boolean ``masks`` ---------------

#: The sam2 options for onnxruntime's exporter, as the README gives them.
ORT_SAM2 = {
    "encoder_outputs": ["image_features_0", "image_features_1", "image_embeddings"],
    "decoder_inputs": ["point_coords", "point_labels", "input_masks", "has_input_masks",
                       "original_image_size"],
    "decoder_outputs": ["low_res_masks", "iou_predictions"],
}


@pytest.fixture(scope="module")
def ort_sam2(tmp_path_factory):
    d = tmp_path_factory.mktemp("ortsam2")
    return export_sam2_like(d / "sam2_image_encoder.onnx", d / "sam2_image_decoder.onnx",
                            onnxruntime_names=True)


def test_onnxruntime_exporter_names_segment_like_samexporter(models, frame, ort_sam2):
    enc, dec = ort_sam2
    ref = _backend(models).segment(frame, _depth())
    backend = Sam2GdinoSegments(  # flat options, as a YAML would give them
        sam2_encoder_path=str(enc), sam2_decoder_path=str(dec), sam2_input_size=SAM_INPUT,
        sam2_points_per_side=16, sam2_points_per_batch=48, sam2_min_area_px=4,
        **{f"sam2_{k}": v for k, v in ORT_SAM2.items()},
        gdino_model_path=str(models["gd"]), gdino_vocab_path=str(models["vocab"]))
    assert backend.sam.decoder.input_type("point_labels") == "tensor(int32)"
    seg = backend.segment(frame, _depth())
    assert seg.labels == ref.labels  # same graph arithmetic, other names: the same segments
    np.testing.assert_array_equal(seg.segment_id, ref.segment_id)


def test_onnxruntime_boolean_masks_output_is_refused_with_the_mapping(models, ort_sam2):
    enc, dec = ort_sam2
    renamed = {k: v for k, v in ORT_SAM2.items() if k != "decoder_outputs"}
    with pytest.raises(ModelSignatureError,
                       match=r"'masks' is boolean.*decoder_outputs: \[low_res_masks, "
                             r"iou_predictions\]"):
        _backend(models, sam2={"encoder_path": str(enc), "decoder_path": str(dec), **renamed})


def test_the_readme_gives_this_mapping():
    """The README's recipe for onnxruntime's exporter is the one these tests run."""
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    block = re.search(r"```yaml\n(\s*sam2_encoder_outputs:.*?)```", readme, re.S)
    assert block, "README lost the onnxruntime SAM2 mapping"
    assert yaml.safe_load(block.group(1)) == {f"sam2_{k}": v for k, v in ORT_SAM2.items()}
