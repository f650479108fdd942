"""KITTI-protocol AP: perfect, empty, hand-computed half-recall and ranking cases."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.evaluate import average_precision, evaluate_detections


def _doors(rng: np.random.Generator, n: int) -> np.ndarray:
    xyz = np.column_stack([rng.uniform(0.5, 5.0, n), rng.uniform(-4, 4, n), np.full(n, 0.5)])
    size = np.column_stack([rng.uniform(0.9, 1.0, n), rng.uniform(0.1, 0.3, n),
                            rng.uniform(2.0, 2.1, n)])
    return np.hstack([xyz, size, rng.uniform(-np.pi, np.pi, (n, 1))])


def _frames(seed: int = 0, n_frames: int = 12):
    rng = np.random.default_rng(seed)
    gts = []
    for _ in range(n_frames):
        boxes = _doors(rng, int(rng.integers(1, 4)))
        boxes[:, 1] = np.linspace(-4, 4, len(boxes) + 2)[1:-1]  # doors never overlap
        gts.append(boxes)
    return gts


@pytest.mark.parametrize("metric", ["3d", "bev"])
@pytest.mark.parametrize("recall_points", [11, 40])
def test_perfect_predictions_with_noise_give_100(metric, recall_points):
    rng = np.random.default_rng(3)
    gts = _frames()
    preds = [g + rng.normal(0, [0.01, 0.01, 0.01, 0.005, 0.002, 0.005, 0.005], g.shape)
             for g in gts]
    scores = [rng.uniform(0.5, 1.0, len(g)) for g in gts]
    ap = average_precision(gts, preds, scores, iou_threshold=0.5, metric=metric,
                           recall_points=recall_points)
    assert ap == pytest.approx(100.0, abs=1e-9)


def test_no_predictions_give_zero():
    gts = _frames()
    empty = [np.zeros((0, 7)) for _ in gts]
    assert average_precision(gts, empty, [np.zeros(0)] * len(gts)) == 0.0
    # predictions that miss every door also give zero
    far = [g + [0, 0, 5.0, 0, 0, 0, 0] for g in gts]
    assert average_precision(gts, far, [np.ones(len(g)) for g in gts]) == 0.0


def test_half_recall_hand_computed():
    # 2 frames x 2 doors; exactly one door per frame found, no false positives.
    # Precision is 1 up to recall 0.5 and undefined (0) beyond:
    #   R40: recall positions 1/40 .. 20/40 -> 20 of 40 -> 50 %
    #   R11: recall positions 0, 0.1, ..., 0.5 -> 6 of 11 -> 54.545 %
    gts = _frames(n_frames=2)
    gts = [np.vstack([g[:1], g[:1] + [0, 2.0, 0, 0, 0, 0, 0]]) for g in gts]
    preds = [g[:1] for g in gts]
    scores = [np.array([0.9]), np.array([0.8])]
    assert average_precision(gts, preds, scores, recall_points=40) == pytest.approx(50.0)
    assert average_precision(gts, preds, scores, recall_points=11) == pytest.approx(600 / 11)


def test_ranking_matters_hand_computed():
    # 2 doors, 3 detections: TP (0.9), FP (0.8), TP (0.7).
    # thresholds 0.9 -> P=1, R=0.5; 0.7 -> P=2/3, R=1.
    # R40: 20 positions at 1.0, 20 at 2/3 -> 83.333 %; R11: 6 at 1.0, 5 at 2/3 -> 84.848 %
    g = _frames(n_frames=1)[0][:1]
    gts = [g, g + [0, 1.5, 0, 0, 0, 0, 0]]
    preds = [np.vstack([g, g + [0, 0, 3.0, 0, 0, 0, 0]]), gts[1]]
    scores = [np.array([0.9, 0.8]), np.array([0.7])]
    assert average_precision(gts, preds, scores) == pytest.approx(100 * (20 + 40 / 3) / 40)
    assert average_precision(gts, preds, scores, recall_points=11) == pytest.approx(
        100 * (6 + 5 * 2 / 3) / 11)


def test_false_positives_and_iou_threshold():
    g = _frames(n_frames=1)[0][:1]
    dup = np.vstack([g, g])
    # a lower-scored duplicate lies below the last TP threshold: it costs nothing
    assert average_precision([g], [dup], [np.array([0.9, 0.8])]) == pytest.approx(100.0)
    # the ground truth takes the best-scored of two duplicates; the other is an FP below it
    assert average_precision([g], [dup], [np.array([0.9, 0.95])]) == pytest.approx(100.0)
    # a miss scored above the TP is an FP at the TP's threshold: precision 1/2 at recall 1
    miss = np.vstack([g, g + [0, 0, 3.0, 0, 0, 0, 0]])
    assert average_precision([g], [miss], [np.array([0.9, 0.95])]) == pytest.approx(50.0)
    # a box shifted by dx/3 along its heading has BEV IoU (2/3) / (4/3) = 0.5
    shifted = g.copy()
    shifted[0, 0] += g[0, 3] / 3 * np.cos(g[0, 6])
    shifted[0, 1] += g[0, 3] / 3 * np.sin(g[0, 6])
    assert average_precision([g], [shifted], [np.ones(1)], 0.51, metric="bev") == 0.0
    assert average_precision([g], [shifted], [np.ones(1)], 0.49, metric="bev") == 100.0


def test_evaluate_detections_keys_and_errors():
    gts = _frames()
    res = evaluate_detections(gts, gts, [np.ones(len(g)) for g in gts])
    assert set(res) == {f"{m}_r{n}@{t}" for m in ("3d", "bev") for n in (11, 40)
                        for t in ("0.3", "0.5")}
    assert all(v == pytest.approx(100.0) for v in res.values())
    with pytest.raises(ValueError, match="equal length"):
        average_precision(gts, gts[:-1], [np.ones(len(g)) for g in gts])
    with pytest.raises(ValueError, match="recall_points"):
        average_precision(gts, gts, [np.ones(len(g)) for g in gts], recall_points=41)
    with pytest.raises(ValueError, match="metric"):
        average_precision(gts, gts, [np.ones(len(g)) for g in gts], metric="2d")
    with pytest.raises(ValueError, match="scores"):
        average_precision(gts[:1], gts[:1], [np.ones(7)])
