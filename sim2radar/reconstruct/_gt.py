"""Access to ground truth for the ``oracle`` backends: a ``WorldFrame``-like object or arrays."""

from __future__ import annotations

import numpy as np

from sim2radar.reconstruct.types import FrameInput, ReconstructionInputError


def gt_array(ground_truth, field: str, frame: FrameInput, backend: str) -> np.ndarray:
    """Return ``ground_truth.<field>`` (or ``ground_truth[field]`` for a mapping, or the array
    itself for ``depth_m`` given as a bare array), checked against the frame size."""
    if ground_truth is None:
        raise ReconstructionInputError(
            f"{frame.name}: the {backend!r} oracle backend needs ground truth; pass "
            "ground_truth=<WorldFrame or dict of arrays> to reconstruct(), or choose another backend"
        )
    if isinstance(ground_truth, np.ndarray):
        arr = ground_truth
    elif isinstance(ground_truth, dict):
        if field not in ground_truth:
            raise ReconstructionInputError(
                f"{frame.name}: ground truth for the {backend!r} oracle lacks {field!r}; "
                f"it has {sorted(ground_truth)}"
            )
        arr = ground_truth[field]
    else:
        if not hasattr(ground_truth, field):
            raise ReconstructionInputError(
                f"{frame.name}: ground truth ({type(ground_truth).__name__}) for the {backend!r} "
                f"oracle has no field {field!r}"
            )
        arr = getattr(ground_truth, field)
    arr = np.asarray(arr)
    if arr.shape[:2] != frame.shape:
        raise ReconstructionInputError(
            f"{frame.name}: ground-truth {field} is {arr.shape[:2]} but the image is {frame.shape}"
        )
    return arr


def majority(values: np.ndarray, segment_id: np.ndarray, n_segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Per segment, the most frequent non-negative value and its pixel fraction.

    Returns
    -------
    winner : (S,) int64; fraction : (S,) float32 in [0, 1] (0 for empty segments).
    """
    seg = segment_id.ravel()
    val = values.ravel().astype(np.int64)
    keep = seg >= 0
    seg, val = seg[keep], val[keep]
    n_val = int(val.max()) + 1 if val.size else 1
    counts = np.bincount(seg * n_val + val, minlength=n_segments * n_val).reshape(n_segments, n_val)
    winner = counts.argmax(axis=1)
    total = counts.sum(axis=1)
    frac = np.where(total > 0, counts.max(axis=1) / np.maximum(total, 1), 0.0)
    return winner, frac.astype(np.float32)
