"""Did a pre-training learn anything? (sim2radar/experiment/learnability.py)"""

from __future__ import annotations

import math

import pytest

from sim2radar.datasets import make_door_frames
from sim2radar.experiment import load_profile
from sim2radar.experiment.learnability import PRIMARY_AP, check_pretraining
from sim2radar.experiment.runner import pretrain_encoder


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    """The smoke detector pre-trained on 16 synthetic door frames for 1 and for 20 epochs."""
    cfg = load_profile("smoke").detector_config("pretrain")
    train = make_door_frames(16, seed=1, points_per_frame=300)
    root = tmp_path_factory.mktemp("learn")
    return {ep: pretrain_encoder(cfg, train, root / f"ep{ep}", seed=0, epochs=ep)
            for ep in (1, 20)}


def test_a_pretraining_that_learned_scores_on_held_out_frames(checkpoints):
    """Frames of other (synthetic) scenes, their own labels: 20 epochs learn doors (measured:
    11 AP), one epoch does not (0 AP); the threshold states whether it was met."""
    held_out = make_door_frames(8, seed=5, points_per_frame=300)
    real = make_door_frames(4, seed=9, points_per_frame=300)
    short = check_pretraining(checkpoints[1], held_out, real, threshold=5.0)
    long = check_pretraining(checkpoints[20], held_out, real, threshold=5.0)
    assert long.sim_ap > short.sim_ap + 5.0
    assert long.met is True and short.met is False
    assert long.sim[PRIMARY_AP] == long.sim_ap and long.sim_frames == 8 and long.real_frames == 4
    assert math.isfinite(long.real_zero_shot_ap)
    assert set(long.to_dict()) >= {"sim_ap", "real_zero_shot_ap", "threshold", "met"}


def test_empty_sets_and_no_threshold(checkpoints):
    c = check_pretraining(checkpoints[1], [], [])
    assert math.isnan(c.sim_ap) and math.isnan(c.real_zero_shot_ap)
    assert c.met is None and c.sim == {} and c.real == {}
