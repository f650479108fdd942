"""The sweep's plan: grid size and order, deduplicated pre-trainings, the pairing of
conditions (same seed, subset and epochs), min_steps, and run identities."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import pytest

from sim2radar.experiment.plan import (
    PretrainSpec,
    epochs_for,
    ids_digest,
    plan_sweep,
    pretrain_key_inputs,
    run_key_inputs,
)
from sim2radar.experiment.profiles import ExperimentProfile, load_profile
from sim2radar.experiment.subsets import real_subset, trial_seed

IDS = [f"world_{w:06d}_f{k:03d}" for w in range(38) for k in range(10)][:371]


def test_paper_grid_pairs_conditions_by_trial():
    profile = load_profile("paper")
    pretrains, runs = plan_sweep(profile, IDS)
    assert len(runs) == 2 * 5 * 5
    # ordered by trial, fraction, condition (baseline first)
    assert [(r.trial, r.fraction, r.condition) for r in runs[:4]] == [
        (0, 0.05, "baseline"), (0, 0.05, "sim-pretrain"), (0, 0.1, "baseline"),
        (0, 0.1, "sim-pretrain")]
    cells = defaultdict(list)
    for r in runs:
        cells[(r.fraction, r.trial)].append(r)
    for (fraction, trial), (base, sim) in cells.items():
        assert base.condition == "baseline" and sim.condition == "sim-pretrain"
        # the only difference between the conditions of a cell is the pre-trained encoder
        assert base.seed == sim.seed == trial_seed(profile.sweep_seed, trial)
        assert base.train_ids == sim.train_ids == tuple(real_subset(IDS, fraction, base.seed))
        assert base.epochs == sim.epochs == 200 and base.n_real == len(base.train_ids)
        assert base.pretrain is None and sim.pretrain.trial == trial
        assert sim.pretrain.seed == base.seed
    assert sorted({r.n_real for r in runs}) == [18, 37, 92, 185, 371]
    # intensity matching on (the paper's §6.1): one pre-training per trial and fraction, its
    # sim intensities matched to exactly the real subset its runs fine-tune on
    assert [(p.sim_role, p.trial, p.fraction, p.epochs) for p in pretrains] == [
        ("sim", t, f, 20) for t in range(5) for f in profile.fractions]
    assert len({id(r.pretrain) for r in runs if r.pretrain}) == 25
    for r in runs:
        if r.pretrain:
            assert r.pretrain.real_ids == r.train_ids and r.pretrain.fraction == r.fraction
    # without matching: one pre-training per trial seed, shared by that trial's fractions
    plain = profile.model_copy(update={"intensity_matching": False})
    pre, runs = plan_sweep(plain, IDS)
    assert [(p.sim_role, p.trial, p.fraction) for p in pre] == [("sim", t, None)
                                                                 for t in range(5)]
    assert len({id(r.pretrain) for r in runs if r.pretrain}) == 5


def test_shared_pretraining_and_ablations():
    profile = ExperimentProfile(detector=Path("x.yaml"), trials=3, fractions=(0.5, 1.0),
                                pretrain_per_trial=False, intensity_matching=False,
                                ablations=("sim-gt-pretrain", "sim-one-material-pretrain"))
    pretrains, runs = plan_sweep(profile, IDS[:40])
    assert len(runs) == 4 * 2 * 3
    assert {(p.sim_role, p.trial) for p in pretrains} == {
        ("sim", None), ("sim-gt", None), ("sim-one-material", None)}
    assert all(p.seed == trial_seed(0, 0) for p in pretrains)
    by_cond = {r.condition: r.pretrain for r in runs if r.trial == 2}
    assert by_cond["baseline"] is None
    assert by_cond["sim-gt-pretrain"].sim_role == "sim-gt"
    assert by_cond["sim-one-material-pretrain"].name == "pretrain-sim-one-material-shared"
    # per trial: one pre-training per (role, trial)
    per_trial = profile.model_copy(update={"pretrain_per_trial": True})
    assert len(plan_sweep(per_trial, IDS[:40])[0]) == 3 * 3
    # a subset of conditions
    pre, runs = plan_sweep(profile, IDS[:40], conditions=["sim-gt-pretrain", "baseline"])
    assert [p.sim_role for p in pre] == ["sim-gt"]
    assert [r.condition for r in runs[:2]] == ["baseline", "sim-gt-pretrain"]
    with pytest.raises(ValueError, match="baseline"):
        plan_sweep(profile, IDS, conditions=["sim-pretrain"])
    with pytest.raises(ValueError, match="known"):
        plan_sweep(profile, IDS, conditions=["baseline", "sim"])


def test_min_steps_raises_epochs_equally_for_both_conditions():
    assert epochs_for(18, 8, 10, None) == 10
    assert epochs_for(18, 8, 10, 300) == 100  # 3 steps per epoch
    assert epochs_for(185, 8, 10, 300) == 13  # 24 steps per epoch -> 312 steps
    assert epochs_for(371, 8, 10, 300) == 10  # 47 steps per epoch: already 470 steps
    with pytest.raises(ValueError):
        epochs_for(0, 8, 10, 300)
    demo = load_profile("demo")
    _, runs = plan_sweep(demo, IDS)
    epochs = {}
    for r in runs:
        assert epochs.setdefault((r.fraction, r.trial), r.epochs) == r.epochs
        steps = r.epochs * -(-r.n_real // demo.batch_size)
        assert steps >= demo.min_steps
    # 371 frames: 5 % -> 18 frames, 3 steps per epoch; 100 % -> 47 steps per epoch
    assert epochs[(0.05, 0)] == -(-demo.min_steps // 3)
    assert epochs[(1.0, 0)] == max(demo.finetune_epochs, -(-demo.min_steps // 47))


def _detector(**changes):
    cfg = load_profile("smoke").detector_config()
    return cfg.with_updates(**changes).model_dump(mode="json") if changes else \
        cfg.model_dump(mode="json")


def test_run_identity():
    profile = load_profile("smoke")
    _, runs = plan_sweep(profile, IDS[:20])
    det = _detector()
    base, sim = runs[0], runs[1]
    k_base = run_key_inputs(base, profile, det)
    k_sim = run_key_inputs(sim, profile, det, pretrain_key="abc")
    json.dumps(k_base, allow_nan=False)  # JSON-able
    assert k_base["train_ids"] == k_sim["train_ids"] == ids_digest(base.train_ids)
    assert k_base != k_sim and k_sim["pretrain"] == "abc"
    keys = [run_key_inputs(r, profile, det, pretrain_key="abc" if r.pretrain else None)
            for r in runs]
    assert len({json.dumps(k, sort_keys=True) for k in keys}) == len(runs)  # all distinct
    # what does not change the result does not change the identity ...
    same = _detector(runtime={"num_threads": 2, "device": "cuda", "checkpoint_every": 7},
                     name="other", data={"root": "/elsewhere"})
    assert run_key_inputs(base, profile, same) == k_base
    # ... what does, does
    assert run_key_inputs(base, profile, _detector(model={"nms_threshold": 0.2})) != k_base
    assert run_key_inputs(base, profile, _detector(augmentation={"gt_sampling": False})) != k_base
    val = profile.model_copy(update={"val_every": 5})
    assert run_key_inputs(base, val, det) != k_base
    with pytest.raises(ValueError, match="pretrain_key"):
        run_key_inputs(sim, profile, det)
    with pytest.raises(ValueError, match="pretrain_key"):
        run_key_inputs(base, profile, det, pretrain_key="abc")

    p = PretrainSpec(condition="sim-pretrain", trial=0, seed=5, sim_role="sim", epochs=20)
    k = pretrain_key_inputs(p, det, {"quantiles": [1.0, 2.0]})
    assert k != pretrain_key_inputs(p, det, None)
    assert k != pretrain_key_inputs(p.model_copy(update={"trial": 1, "seed": 6}), det,
                                    {"quantiles": [1.0, 2.0]})
    json.dumps(k, allow_nan=False)
    d = runs[1].model_dump(mode="json")
    assert d["pretrain"]["sim_role"] == "sim" and isinstance(d["train_ids"], list)
    json.dumps(d)


def test_the_diagnosis_arms_share_and_separate_what_they_should():
    """sim-pretrain-lowlr loads sim-pretrain's pre-training (one pre-training, two fine-tuning
    protocols) but is its own run: its encoder learning-rate share is in its key; ref-pretrain
    pre-trains on its own dataset; every pre-training holds out the profile's split."""
    from sim2radar.experiment.plan import condition_config

    profile = ExperimentProfile(detector=Path("x.yaml"), trials=2, fractions=(0.05, 0.25),
                                conditions=("baseline", "sim-pretrain", "ref-pretrain",
                                            "sim-pretrain-lowlr"))
    pretrains, runs = plan_sweep(profile, IDS[:80])
    assert {p.sim_role for p in pretrains} == {"sim", "ref"}
    assert all(p.holdout_split == "val" for p in pretrains)
    assert len(pretrains) == 2 * 2 * 2          # roles x trials x fractions (matching on)
    cell = {r.condition: r for r in runs if r.trial == 1 and r.fraction == 0.25}
    assert cell["sim-pretrain-lowlr"].pretrain is cell["sim-pretrain"].pretrain
    assert cell["ref-pretrain"].pretrain.sim_role == "ref"
    cfg = load_profile("smoke").detector_config()
    det = cfg.model_dump(mode="json")
    assert condition_config(cfg, "sim-pretrain") is cfg
    # the condition's share replaces the sweep's, nothing else: the dump its key hashes is
    # the sweep's with that one field changed
    low = condition_config(cfg, "sim-pretrain-lowlr").model_dump(mode="json")
    assert low == {**det, "optimization": {**det["optimization"], "encoder_lr_scale": 0.1}}
    k_sim = run_key_inputs(cell["sim-pretrain"], profile, det, pretrain_key="p")
    k_low = run_key_inputs(cell["sim-pretrain-lowlr"], profile, low, pretrain_key="p")
    assert k_low != k_sim and k_low["detector"]["optimization"]["encoder_lr_scale"] == 0.1
    # the default share (1.0) is not in a key: runs planned before it existed keep theirs
    assert "encoder_lr_scale" not in k_sim["detector"]["optimization"]
    # the held-out split is part of a pre-training's identity
    p = pretrains[0]
    whole = p.model_copy(update={"holdout_split": None})
    assert pretrain_key_inputs(p, det, None) != pretrain_key_inputs(whole, det, None)
