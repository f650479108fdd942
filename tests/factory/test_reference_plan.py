"""The reference dataset's plan: paper-sized splits by world, disjoint worlds."""

from __future__ import annotations

import pytest

from sim2radar.factory.reference import PAPER_SPLIT_FRAMES, plan_reference


def test_default_plan_is_sized_exactly_like_the_paper():
    plan = plan_reference(100_000, frames_per_world=10)
    # the paper states 617 frames but its splits add up to 371 + 92 + 155 = 618
    assert plan.n_frames == 618
    assert plan.split_frames() == PAPER_SPLIT_FRAMES           # 371 / 92 / 155
    assert [len(plan.splits[s]) for s in ("train", "val", "test")] == [38, 10, 16]
    # splits share no world, every world is in one split, seeds are consecutive
    all_seeds = [s for v in plan.splits.values() for s in v]
    assert sorted(all_seeds) == list(plan.seeds) == list(range(100_000, 100_064))
    assert plan.frames_by_seed[100_037] == 1                   # train's last world: 371 - 370


def test_explicit_worlds_split_by_world_in_the_paper_proportions():
    plan = plan_reference(500, worlds=20, frames_per_world=4, seed=3)
    assert plan.n_frames == 80 and set(plan.frames_by_seed.values()) == {4}
    sizes = {k: len(v) for k, v in plan.splits.items()}
    assert sizes == {"train": 12, "val": 3, "test": 5}        # 60 % / 15 % / 25 % of 20
    assert set().union(*map(set, plan.splits.values())) == set(range(500, 520))
    assert plan_reference(500, worlds=20, frames_per_world=4, seed=3) == plan  # deterministic


def test_bad_plans_are_refused_with_the_field_named():
    with pytest.raises(ValueError, match="frames_per_world"):
        plan_reference(0, frames_per_world=0)
    with pytest.raises(ValueError, match="worlds"):
        plan_reference(0, worlds=0)
    with pytest.raises(ValueError, match="first_seed"):
        plan_reference(-1)


def test_stored_dataset_domain_names_the_reference_radar_only_on_ground_truth():
    from sim2radar.factory.reference import DOMAIN_LABEL, stored_dataset_domain

    assert stored_dataset_domain("signal", "ground_truth") == DOMAIN_LABEL
    assert stored_dataset_domain("signal", "reconstructed").startswith("simulated (signal")
    assert stored_dataset_domain("raytrace", "ground_truth").startswith("simulated (raytrace")
