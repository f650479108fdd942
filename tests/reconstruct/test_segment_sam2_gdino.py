"""Tests for the ``sam2-gdino`` segmentation backend with tiny test-built ONNX models."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct._onnx import ModelSignatureError
from sim2radar.reconstruct.segment_sam2_gdino import (
    Detections,
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
    dets = backend.last_detections
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
