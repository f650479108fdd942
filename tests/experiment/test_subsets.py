"""Trial seeds and real subsets: seed-determined, nested across fractions, the paper's N."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.experiment.subsets import n_real_frames, real_subset, trial_seed

FRACTIONS = (0.05, 0.10, 0.25, 0.50, 1.00)
IDS = [f"world_{w:06d}_f{k:03d}" for w in range(38) for k in range(10)][:371]


def test_trial_seed_is_a_spawned_seed_sequence():
    for sweep, trial in ((0, 0), (0, 4), (7, 2)):
        child = np.random.SeedSequence(sweep).spawn(trial + 1)[trial]
        assert trial_seed(sweep, trial) == int(child.generate_state(1, dtype=np.uint32)[0])
    seeds = [trial_seed(0, t) for t in range(5)]
    assert len(set(seeds)) == 5 and all(0 <= s < 2**32 for s in seeds)
    assert seeds == [trial_seed(0, t) for t in range(5)]  # deterministic
    assert trial_seed(1, 0) != trial_seed(0, 0)  # the sweep seed matters
    with pytest.raises(ValueError):
        trial_seed(0, -1)


def test_paper_subset_sizes():
    """Table 1's N: 18 / 37 / 92 / 185 / 371 of 371 train frames."""
    assert [len(real_subset(IDS, f, seed=3)) for f in FRACTIONS] == [18, 37, 92, 185, 371]
    assert [n_real_frames(371, f) for f in FRACTIONS] == [18, 37, 92, 185, 371]
    assert n_real_frames(100, 0.29) == 29  # 0.29 * 100 = 28.999999999999996 in floating point
    assert n_real_frames(10, 0.01) == 1  # at least one frame
    with pytest.raises(ValueError, match="fraction"):
        n_real_frames(10, 0.0)
    with pytest.raises(ValueError, match="empty"):
        real_subset([], 0.5, 0)


def test_subsets_are_nested_and_seed_determined():
    seed = trial_seed(0, 1)
    subsets = [real_subset(IDS, f, seed) for f in FRACTIONS]
    for small, large in zip(subsets, subsets[1:], strict=False):
        assert large[: len(small)] == small  # nested: a prefix of the same permutation
    assert sorted(subsets[-1]) == sorted(IDS)  # 100 % is the whole split, once each
    assert real_subset(IDS, 0.25, seed) == subsets[2]  # same seed, same subset
    # the listing order of the split does not matter, the seed does
    assert real_subset(IDS[::-1], 0.25, seed) == subsets[2]
    other = real_subset(IDS, 0.25, trial_seed(0, 2))
    assert other != subsets[2] and len(set(other) & set(subsets[2])) < len(other)
    # a trial's 5 % subset is a random draw, not the first frames of the split
    assert subsets[0] != sorted(IDS)[:18]
    with pytest.raises(ValueError, match="duplicates"):
        real_subset(IDS + IDS[:1], 0.5, seed)
