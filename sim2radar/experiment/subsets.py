"""Trial seeds and the real-data subsets of a sweep.

One seed per trial (:func:`trial_seed`) fixes everything that varies between trials: the real
subset (:func:`real_subset`), the head's initial weights and the data order of every training
run of that trial (:func:`sim2radar.detect.train.train`). All conditions of a trial use the same
seed, so a trial's conditions differ only in the encoder's initialisation (the paper's "key
comparison", §6.1) and the comparison can be paired by trial.

Subsets are nested: a trial's 5 % subset lies inside its 10 % subset, and so on, because every
fraction takes the first ``n`` ids of the same permutation. With the paper's 371 train frames
the sizes are 18 / 37 / 92 / 185 / 371 (Table 1's N).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence

import numpy as np

__all__ = ["n_real_frames", "real_subset", "trial_seed"]


def trial_seed(sweep_seed: int, trial: int) -> int:
    """Seed of trial ``trial`` of a sweep: the first 32-bit word of
    ``numpy.random.SeedSequence(sweep_seed, spawn_key=(trial,))``, i.e. of
    ``SeedSequence(sweep_seed).spawn(trial + 1)[trial]``.

    Spawned sequences are independent streams (NumPy's recommended way to derive seeds); the
    value is in [0, 2**32) so it fits ``torch.manual_seed`` and an int64 column.
    """
    if int(sweep_seed) < 0 or int(trial) < 0:
        raise ValueError(f"sweep_seed and trial must be >= 0, got {sweep_seed}, {trial}")
    seq = np.random.SeedSequence(int(sweep_seed), spawn_key=(int(trial),))
    return int(seq.generate_state(1, dtype=np.uint32)[0])


def n_real_frames(n_train: int, fraction: float) -> int:
    """Frames of a fraction: ``floor(fraction * n_train)``, at least 1.

    A tolerance of 1e-9 frames keeps products like ``0.29 * 100 = 28.999999999999996`` at 29.
    """
    if n_train < 1:
        raise ValueError(f"the real train split is empty (n_train={n_train})")
    if not 0.0 < float(fraction) <= 1.0:
        raise ValueError(f"fraction must lie in (0, 1], got {fraction}")
    return max(1, min(int(n_train), math.floor(float(fraction) * int(n_train) + 1e-9)))


def real_subset(train_ids: Sequence[str], fraction: float, seed: int) -> list[str]:
    """The ids a trial trains on at one fraction.

    Parameters
    ----------
    train_ids : the real train split's frame ids (order does not matter: they are sorted first).
    fraction : share of the split, in (0, 1].
    seed : the trial's seed (:func:`trial_seed`); the permutation is
        ``numpy.random.default_rng(seed).permutation(len(train_ids))`` (a stream distinct from
        the training runs' ``default_rng([seed, epoch])``).

    Returns
    -------
    list of :func:`n_real_frames` ids, in permutation order: the first ``n`` of the trial's
    permutation, so subsets of one seed are nested across fractions.
    """
    ids = sorted(str(i) for i in train_ids)
    dup = sorted(i for i, k in Counter(ids).items() if k > 1)
    if dup:
        raise ValueError(f"train_ids contains duplicates, e.g. {dup[:3]}")
    n = n_real_frames(len(ids), fraction)
    order = np.random.default_rng(int(seed)).permutation(len(ids))
    return [ids[i] for i in order[:n]]
