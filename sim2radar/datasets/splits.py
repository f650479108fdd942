"""Dataset splits."""

from __future__ import annotations

import random
from collections.abc import Sequence

__all__ = ["split_groups"]


def split_groups(group_ids: Sequence[str], seed: int = 0,
                 fractions: tuple[float, float, float] = (0.7, 0.15, 0.15)) -> dict[str, list]:
    """Seeded train/val/test split of groups (e.g. worlds or buildings: the frames of one group
    never straddle splits, so no scene leaks from train into test).

    With fewer than three groups, every group goes to train (val/test stay empty) rather than
    leaving train empty. Ids are sorted within each split.
    """
    ids = sorted(dict.fromkeys(group_ids))
    random.Random(int(seed)).shuffle(ids)
    n = len(ids)
    if n < 3:
        return {"train": sorted(ids), "val": [], "test": []}
    n_val = max(1, round(fractions[1] * n))
    n_test = max(1, round(fractions[2] * n))
    n_train = max(1, n - n_val - n_test)
    return {"train": sorted(ids[:n_train]), "val": sorted(ids[n_train:n_train + n_val]),
            "test": sorted(ids[n_train + n_val:])}
