"""KITTI-protocol AP: perfect, empty, hand-computed half-recall and ranking cases, in both
threshold modes (``"all"``: every true-positive score; ``"devkit"``: OpenPCDet's 41 sampled
thresholds), and hand-computed cases where the two differ."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from sim2radar.evaluate import average_precision, evaluate_detections, precision_recall
from sim2radar.evaluate.ap import devkit_thresholds

_exact = functools.partial(average_precision, thresholds="all")


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
                           recall_points=recall_points, thresholds="all")
    assert ap == pytest.approx(100.0, abs=1e-9)
    # the devkit reaches 100 only with >= 41 ground truths (see test_devkit_small_sets)
    gts = _frames(seed=1, n_frames=40)
    assert sum(len(g) for g in gts) >= 41
    preds = [g + rng.normal(0, [0.01, 0.01, 0.01, 0.005, 0.002, 0.005, 0.005], g.shape)
             for g in gts]
    scores = [rng.uniform(0.5, 1.0, len(g)) for g in gts]
    ap = average_precision(gts, preds, scores, iou_threshold=0.5, metric=metric,
                           recall_points=recall_points, thresholds="devkit")
    assert ap == pytest.approx(100.0, abs=1e-9)


@pytest.mark.parametrize("mode", ["devkit", "all"])
def test_no_predictions_give_zero(mode):
    gts = _frames()
    empty = [np.zeros((0, 7)) for _ in gts]
    assert average_precision(gts, empty, [np.zeros(0)] * len(gts), thresholds=mode) == 0.0
    # predictions that miss every door also give zero
    far = [g + [0, 0, 5.0, 0, 0, 0, 0] for g in gts]
    assert average_precision(gts, far, [np.ones(len(g)) for g in gts], thresholds=mode) == 0.0


def test_half_recall_hand_computed():
    # 2 frames x 2 doors; exactly one door per frame found, no false positives.
    # Precision is 1 up to recall 0.5 and undefined (0) beyond:
    #   R40: recall positions 1/40 .. 20/40 -> 20 of 40 -> 50 %
    #   R11: recall positions 0, 0.1, ..., 0.5 -> 6 of 11 -> 54.545 %
    gts = _frames(n_frames=2)
    gts = [np.vstack([g[:1], g[:1] + [0, 2.0, 0, 0, 0, 0, 0]]) for g in gts]
    preds = [g[:1] for g in gts]
    scores = [np.array([0.9]), np.array([0.8])]
    assert average_precision(gts, preds, scores, recall_points=40,
                             thresholds="all") == pytest.approx(50.0)
    assert average_precision(gts, preds, scores, recall_points=11,
                             thresholds="all") == pytest.approx(600 / 11)


def test_ranking_matters_hand_computed():
    # 2 doors, 3 detections: TP (0.9), FP (0.8), TP (0.7).
    # thresholds 0.9 -> P=1, R=0.5; 0.7 -> P=2/3, R=1.
    # R40: 20 positions at 1.0, 20 at 2/3 -> 83.333 %; R11: 6 at 1.0, 5 at 2/3 -> 84.848 %
    g = _frames(n_frames=1)[0][:1]
    gts = [g, g + [0, 1.5, 0, 0, 0, 0, 0]]
    preds = [np.vstack([g, g + [0, 0, 3.0, 0, 0, 0, 0]]), gts[1]]
    scores = [np.array([0.9, 0.8]), np.array([0.7])]
    assert average_precision(gts, preds, scores, thresholds="all") == pytest.approx(
        100 * (20 + 40 / 3) / 40)
    assert average_precision(gts, preds, scores, recall_points=11,
                             thresholds="all") == pytest.approx(100 * (6 + 5 * 2 / 3) / 11)
    # devkit: both TP scores are thresholds (0.9: P=1; 0.7: P=2/3), read as recall 0 and 1/40;
    # R40 sums entries 1..40 -> (2/3) / 40; R11 sums entries 0, 4, ..., 40 -> 1 / 11
    assert average_precision(gts, preds, scores) == pytest.approx(100 * (2 / 3) / 40)
    assert average_precision(gts, preds, scores, recall_points=11) == pytest.approx(100 / 11)


def test_false_positives_and_iou_threshold():
    # one ground truth: the exact recall positions (the devkit needs >= 41, see below)
    g = _frames(n_frames=1)[0][:1]
    dup = np.vstack([g, g])
    # a lower-scored duplicate lies below the last TP threshold: it costs nothing
    assert _exact([g], [dup], [np.array([0.9, 0.8])]) == pytest.approx(100.0)
    # the ground truth takes the best-scored of two duplicates; the other is an FP below it
    assert _exact([g], [dup], [np.array([0.9, 0.95])]) == pytest.approx(100.0)
    # a miss scored above the TP is an FP at the TP's threshold: precision 1/2 at recall 1
    miss = np.vstack([g, g + [0, 0, 3.0, 0, 0, 0, 0]])
    assert _exact([g], [miss], [np.array([0.9, 0.95])]) == pytest.approx(50.0)
    # a box shifted by dx/3 along its heading has BEV IoU (2/3) / (4/3) = 0.5
    shifted = g.copy()
    shifted[0, 0] += g[0, 3] / 3 * np.cos(g[0, 6])
    shifted[0, 1] += g[0, 3] / 3 * np.sin(g[0, 6])
    assert _exact([g], [shifted], [np.ones(1)], 0.51, metric="bev") == 0.0
    assert _exact([g], [shifted], [np.ones(1)], 0.49, metric="bev") == 100.0


def test_evaluate_detections_keys_and_errors():
    gts = _frames()
    res = evaluate_detections(gts, gts, [np.ones(len(g)) for g in gts], thresholds="all")
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
    with pytest.raises(ValueError, match="thresholds"):
        average_precision(gts, gts, [np.ones(len(g)) for g in gts], thresholds="some")
    with pytest.raises(ValueError, match="thresholds"):
        evaluate_detections(gts, gts, [np.ones(len(g)) for g in gts], thresholds="exact")


# ------------------------------------------------------------------------------ devkit mode
def _one_door_frames(n: int) -> list[np.ndarray]:
    """``n`` frames with one door each (identical boxes: each frame is matched on its own)."""
    g = _frames(n_frames=1)[0][:1]
    return [g.copy() for _ in range(n)]


@pytest.mark.parametrize(("n", "r40", "r11"), [
    (1, 0.0, 100 / 11),          # one threshold, read as recall 0: only R11's entry 0
    (10, 22.5, 300 / 11),        # thresholds 0..9 -> R40 entries 1..9, R11 entries 0, 4, 8
    (40, 97.5, 1000 / 11),       # thresholds 0..39: entry 40 missing
    (41, 100.0, 100.0),          # from 41 ground truths on, all 41 entries exist
])
def test_devkit_small_sets(n, r40, r11):
    """n perfectly detected boxes: the devkit reads threshold k (recall (k+1)/n) as recall k/40,
    so below 41 ground truths it under-reports; the exact mode gives 100 throughout."""
    gts = _one_door_frames(n)
    scores = [np.array([1.0 - i / 100]) for i in range(n)]
    assert average_precision(gts, gts, scores, recall_points=40) == pytest.approx(r40)
    assert average_precision(gts, gts, scores, recall_points=11) == pytest.approx(r11)
    for rp in (11, 40):
        assert average_precision(gts, gts, scores, recall_points=rp,
                                 thresholds="all") == pytest.approx(100.0)


def _eighty_doors(n_found: int):
    """80 frames x 1 door; the first ``n_found`` detected exactly with scores 0.99, 0.98, ...;
    one false positive ranked between TP 10 and TP 11, two between TP 30 and TP 31."""
    gts = _one_door_frames(80)
    far = gts[0] + [0, 0, 3.0, 0, 0, 0, 0]  # overlaps nothing
    preds, scores = [], []
    for k in range(80):
        boxes, sc = [], []
        if k < n_found:
            boxes.append(gts[k])
            sc.append(1.0 - (k + 1) / 100)
        if k == 0:
            boxes += [far, far, far]
            sc += [0.895, 0.695, 0.694]
        preds.append(np.vstack(boxes) if boxes else np.zeros((0, 7)))
        scores.append(np.array(sc))
    return gts, preds, scores


def test_devkit_hand_computed_where_the_modes_differ():
    """80 ground truths, 59 found (highest recall 59/80 = 0.7375, just below 30/40).

    Precision at t true positives: p(t) = 1 for t <= 10, t/(t+1) for 11..30, t/(t+3) for
    31..59. The devkit's thresholds for 80 ground truths are the scores of TP 1, 2, 4, ..., 58
    and, always, the last one, TP 59: 31 thresholds, entry j (j >= 1) at TP 2j and entry 30 at
    TP 59. Interpolated precision (max over lower thresholds): 1 for j <= 5, p(30) = 30/31
    for j = 6..15, p(59) = 59/62 for j = 16..30, 0 for j = 31..40:
        devkit R40 = (5 + 10 * 30/31 + 15 * 59/62) / 40.
    The exact mode reads recall j/40 <= 59/80 only for j <= 29:
        all R40    = (5 + 10 * 30/31 + 14 * 59/62) / 40   (2.38 points lower).
    R11 agrees: entries 0, 4 -> 1; 8, 12 -> 30/31; 16..28 -> 59/62; 32..40 -> 0, and the exact
    recall positions 0..0.7 hit the same values.
    """
    gts, preds, scores = _eighty_doors(59)
    thr, prec, rec = precision_recall(gts, preds, scores)
    tp_counts = [1, *range(2, 59, 2), 59]
    assert thr == pytest.approx([1.0 - t / 100 for t in tp_counts])
    assert rec == pytest.approx([t / 80 for t in tp_counts])
    devkit = 100 * (5 + 10 * 30 / 31 + 15 * 59 / 62) / 40
    exact = 100 * (5 + 10 * 30 / 31 + 14 * 59 / 62) / 40
    assert average_precision(gts, preds, scores) == pytest.approx(devkit)
    assert average_precision(gts, preds, scores, thresholds="all") == pytest.approx(exact)
    assert devkit - exact == pytest.approx(100 * 59 / 62 / 40)
    r11 = 100 * (2 + 2 * 30 / 31 + 4 * 59 / 62) / 11
    assert average_precision(gts, preds, scores, recall_points=11) == pytest.approx(r11)
    assert average_precision(gts, preds, scores, recall_points=11,
                             thresholds="all") == pytest.approx(r11)
    # with 60 found, entry 30 is TP 60 = recall 60/80 = 30/40 exactly: the modes agree
    gts, preds, scores = _eighty_doors(60)
    both = [average_precision(gts, preds, scores, thresholds=m) for m in ("devkit", "all")]
    assert both[0] == pytest.approx(both[1])
    assert both[0] == pytest.approx(100 * (5 + 10 * 30 / 31 + 15 * 60 / 63) / 40)


def test_devkit_thresholds_sampling():
    # 80 ground truths, all found: TP 1, 2, 4, ..., 80 -> 41 thresholds (recall 1/80, k/40)
    scores = 1.0 - np.arange(1, 81) / 100
    thr = devkit_thresholds(scores[::-1].copy(), 80)  # input order does not matter
    assert thr == pytest.approx(1.0 - np.array([1, *range(2, 81, 2)]) / 100)
    # 1,000 ground truths: never more than 41 thresholds, duplicates kept as the devkit does
    rng = np.random.default_rng(0)
    many = np.round(rng.uniform(size=900), 2)
    thr = devkit_thresholds(many, 1000)
    assert thr.size <= 41 and np.all(np.diff(thr) <= 0)
    # fewer than 41 ground truths: every true-positive score is a threshold
    assert devkit_thresholds(np.array([0.3, 0.9, 0.5]), 5) == pytest.approx([0.9, 0.5, 0.3])
    assert devkit_thresholds(np.zeros(0), 5).size == 0
