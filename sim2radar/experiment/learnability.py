"""Did a pre-training learn anything? The checks a pre-trained detector is held to.

A sim pre-training transfers only its encoder, but whether it learned the task at all is
measured on the whole pre-trained detector (encoder and head), before any fine-tuning:

* **held-out sim AP** — 3D AP (KITTI protocol, R40, IoU 0.3) on simulated frames of worlds it
  never saw, against their own (simulated) labels: can the simulated task be learned and
  generalise across worlds? A pre-training near 0 here learned nothing a transfer could carry.
* **zero-shot real AP** — the same AP on the real (or proxy-real) validation split, with no
  fine-tuning: how much of what it learned already holds in the other domain.

A condition may declare a pre-registered learnability threshold on the held-out sim AP; the
check states whether it was met and never selects or drops a run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["PRIMARY_AP", "PretrainingCheck", "check_pretraining"]

#: The AP column a pre-training is judged by (the protocol's metric: 3D AP, R40, IoU 0.3).
PRIMARY_AP = "ap_3d_r40_iou03"


@dataclass(frozen=True)
class PretrainingCheck:
    """What one pre-training measures before fine-tuning.

    Attributes
    ----------
    sim_ap, real_zero_shot_ap : float [%] — :data:`PRIMARY_AP` on held-out simulated frames
        and on the real validation frames (NaN when that set is empty).
    sim_frames, real_frames : int — frames evaluated.
    threshold : float or None [%] — the pre-registered learnability threshold on ``sim_ap``.
    sim, real : dict — every AP column (:func:`sim2radar.experiment.runner.test_ap`).
    """

    sim_ap: float
    real_zero_shot_ap: float
    sim_frames: int
    real_frames: int
    threshold: float | None = None
    sim: dict[str, float] = field(default_factory=dict)
    real: dict[str, float] = field(default_factory=dict)

    @property
    def met(self) -> bool | None:
        """Whether ``sim_ap`` reached the threshold (None without a threshold or a sim AP)."""
        if self.threshold is None or math.isnan(self.sim_ap):
            return None
        return bool(self.sim_ap >= self.threshold)

    def to_dict(self) -> dict:
        return {"sim_ap": self.sim_ap, "real_zero_shot_ap": self.real_zero_shot_ap,
                "sim_frames": self.sim_frames, "real_frames": self.real_frames,
                "threshold": self.threshold, "met": self.met, "sim": dict(self.sim),
                "real": dict(self.real)}


def check_pretraining(checkpoint: str | Path, sim_frames: Sequence, real_frames: Sequence, *,
                      threshold: float | None = None, device=None) -> PretrainingCheck:
    """Evaluate a pre-trained detector (``checkpoint``, :func:`sim2radar.experiment.runner.
    pretrain_encoder`'s) on held-out simulated ``sim_frames`` (intensities as it was trained
    on them) and zero-shot on the real validation ``real_frames``.

    Parameters
    ----------
    checkpoint : path of the pre-training's ``last.pt``.
    sim_frames, real_frames : sequences of :class:`sim2radar.datasets.Frame` (either may be
        empty: its AP is NaN).
    threshold : float, optional [%] — pre-registered learnability threshold on the sim AP.
    """
    from sim2radar.detect.train import load_checkpoint
    from sim2radar.experiment.runner import test_ap

    model, _ = load_checkpoint(checkpoint, device)
    sim = test_ap(model, list(sim_frames)) if len(sim_frames) else {}
    real = test_ap(model, list(real_frames)) if len(real_frames) else {}
    return PretrainingCheck(
        sim_ap=float(sim.get(PRIMARY_AP, math.nan)),
        real_zero_shot_ap=float(real.get(PRIMARY_AP, math.nan)),
        sim_frames=len(sim_frames), real_frames=len(real_frames),
        threshold=None if threshold is None else float(threshold), sim=sim, real=real)
