"""Dataset figures from per-frame outcome records (sim2radar.evaluate.dataset)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.evaluate.dataset import compare_frames, finite_mean, geometry_metrics, stage_seconds
from sim2radar.tasks.common import Outcome


def _frame(n_points, n_labels, tp, n_gt, near, timings):
    f = Outcome("w_f000", "ok", seed=0, index=0, timings_s=dict(timings), measured={
        "n_points": {"reconstructed": n_points}, "n_labels": {"reconstructed": n_labels},
        "n_gt_doors": n_gt, "gt_points_near": {"reconstructed": near}})
    if n_gt or n_labels:
        f.measured["label_match"] = {"reconstructed": {"tp": tp, "n_pred": n_labels,
                                                       "n_gt": n_gt}}
    return f


def test_recall_and_precision_pool_matches_over_frames():
    frames = [_frame(100, 2, 1, 2, [5, 0], {"simulate": 1.0}),
              _frame(50, 1, 1, 1, [3], {"simulate": 3.0, "reconstruct": 2.0})]
    m = geometry_metrics(frames, ["reconstructed"])["reconstructed"]
    assert m["frames"] == 2 and m["points_per_frame"] == 75.0
    assert m["label_recall"] == pytest.approx(2 / 3) and m["label_precision"] == pytest.approx(2 / 3)
    assert m["frac_gt_doors_with_points"] == pytest.approx(2 / 3)
    assert stage_seconds(frames) == {"reconstruct": 2.0, "simulate": 2.0}


def test_without_ground_truth_recall_and_precision_are_undefined_not_zero():
    frames = [_frame(80, 3, 0, 0, [], {})]
    frames[0].measured.pop("label_match", None)
    m = geometry_metrics(frames, ["reconstructed"])["reconstructed"]
    assert math.isnan(m["label_recall"]) and math.isnan(m["label_precision"])
    assert math.isnan(finite_mean([None, float("nan")]))


def test_compare_frames_points_ratio_and_chamfer():
    gt = np.array([[0, 0, 0, 1], [1, 0, 0, 1]], np.float32)
    rec = np.array([[0, 0.1, 0, 1]], np.float32)
    c = compare_frames(gt, rec)
    assert c["points_ratio"] == 0.5
    assert c["chamfer_m"] > 0
    assert math.isnan(compare_frames(gt[:0], rec)["points_ratio"])


def test_labels_equal_to_the_ground_truth_match_one_to_one_without_the_iou():
    from sim2radar.evaluate.reconstruction import match_boxes

    boxes = np.array([[3, 1, 1, 1, 0.2, 2, 0.1], [3, 1.5, 1, 1, 0.2, 2, 0.1],
                      [6, -2, 1, 0.9, 0.17, 2.1, 1.5]])
    fast = match_boxes(boxes, boxes.copy())
    full = match_boxes(boxes, boxes.copy(), ignore=np.zeros((0, 7)))  # the IoU path
    assert fast["tp"] == full["tp"] == 3 and fast["n_pred"] == full["n_pred"] == 3
    np.testing.assert_allclose(fast["ious"], full["ious"], atol=1e-6)


def test_dataset_figures_and_the_factory_tasks_do_not_import_torch():
    import subprocess
    import sys

    code = ("import sys, sim2radar.tasks.dataset, sim2radar.evaluate.dataset, sim2radar.evaluate; "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False", out.stderr
