"""Did a pre-training learn anything? The checks a pre-trained detector is held to.

A sim pre-training transfers only its encoder, but whether it learned the task at all is
measured on the whole pre-trained detector (encoder and head), before any fine-tuning:

* **held-out sim AP** — 3D AP (KITTI protocol, R40, IoU 0.3) on simulated frames of worlds it
  never saw, against their own (simulated) labels: can the simulated task be learned and
  generalise across worlds? A pre-training near 0 here learned nothing a transfer could carry.
* **zero-shot real AP** — the same AP on the real (or proxy-real) validation split, with no
  fine-tuning: how much of what it learned already holds in the other domain.
* **training AP** — the same AP on its own training frames: a pre-training low here did not
  even fit the simulated task (too little signal or too short); high here but low on the
  held-out worlds, it memorised worlds rather than learning doors.

A condition may declare a pre-registered learnability threshold on the held-out sim AP; the
check states whether it was met and never selects or drops a run.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["CHECK_COLUMNS", "PRIMARY_AP", "PretrainingCheck", "check_pretraining",
           "pretraining_table"]

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
    train_ap : float [%] — :data:`PRIMARY_AP` on its own training frames (NaN: not given).
    train_frames : int — training frames evaluated.
    train : dict — every AP column on them.
    """

    sim_ap: float
    real_zero_shot_ap: float
    sim_frames: int
    real_frames: int
    threshold: float | None = None
    sim: dict[str, float] = field(default_factory=dict)
    real: dict[str, float] = field(default_factory=dict)
    train_ap: float = math.nan
    train_frames: int = 0
    train: dict[str, float] = field(default_factory=dict)

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
                "real": dict(self.real), "train_ap": self.train_ap,
                "train_frames": self.train_frames, "train": dict(self.train)}

    @classmethod
    def from_dict(cls, d: dict) -> PretrainingCheck:
        """:meth:`to_dict`'s form (``met`` is derived, not read)."""
        return cls(float(d["sim_ap"]), float(d["real_zero_shot_ap"]), int(d["sim_frames"]),
                   int(d["real_frames"]), d.get("threshold"), dict(d.get("sim") or {}),
                   dict(d.get("real") or {}), float(d.get("train_ap", math.nan)),
                   int(d.get("train_frames", 0)), dict(d.get("train") or {}))


def check_pretraining(checkpoint: str | Path, sim_frames: Sequence, real_frames: Sequence, *,
                      threshold: float | None = None, train_frames: Sequence = (),
                      device=None) -> PretrainingCheck:
    """Evaluate a pre-trained detector (``checkpoint``, :func:`sim2radar.experiment.runner.
    pretrain_encoder`'s) on held-out simulated ``sim_frames`` (intensities as it was trained
    on them) and zero-shot on the real validation ``real_frames``.

    Parameters
    ----------
    checkpoint : path of the pre-training's ``last.pt``.
    sim_frames, real_frames : sequences of :class:`sim2radar.datasets.Frame` (either may be
        empty: its AP is NaN).
    threshold : float, optional [%] — pre-registered learnability threshold on the sim AP.
    train_frames : its own training frames (intensities as trained on), optional.
    """
    from sim2radar.detect.train import load_checkpoint
    from sim2radar.experiment.runner import test_ap

    model, _ = load_checkpoint(checkpoint, device)
    sim = test_ap(model, list(sim_frames)) if len(sim_frames) else {}
    real = test_ap(model, list(real_frames)) if len(real_frames) else {}
    train = test_ap(model, list(train_frames)) if len(train_frames) else {}
    return PretrainingCheck(
        sim_ap=float(sim.get(PRIMARY_AP, math.nan)),
        real_zero_shot_ap=float(real.get(PRIMARY_AP, math.nan)),
        sim_frames=len(sim_frames), real_frames=len(real_frames),
        threshold=None if threshold is None else float(threshold), sim=sim, real=real,
        train_ap=float(train.get(PRIMARY_AP, math.nan)), train_frames=len(train_frames),
        train=train)


#: the checks of a pre-training row (``experiment_pretrain`` columns), as reported
CHECK_COLUMNS = {"heldout": "heldout_ap_3d_r40_iou03", "zero_shot": "zero_shot_ap_3d_r40_iou03",
                 "train": "train_ap_3d_r40_iou03"}


def _finite(v) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else float(v)


def _spread(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"mean": None, "std": None, "min": None, "max": None}
    v = np.asarray(values, dtype=np.float64)
    return {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else None,
            "min": float(v.min()), "max": float(v.max())}


def pretraining_table(rows: Sequence[Mapping], thresholds: Mapping[str, float] | None = None,
                      conditions: Sequence[str] | None = None) -> dict:
    """The sweep's pre-trainings as the report, ``stats.json`` and the dashboard show them.

    Parameters
    ----------
    rows : ``experiment_pretrain`` rows (``pretrainings.parquet``).
    thresholds : the profile's pre-registered ``learnability_thresholds`` (condition -> held-out
        sim AP [%]); a pre-training is judged against the threshold of each condition that
        loads it. It is reported, never used to select or drop a run.
    conditions : conditions to summarise, in order (default: those the rows name).

    Returns
    -------
    dict::

        {"rows": [{"id", "role", "conditions", "trial", "fraction", "n_sim_frames",
                   "n_heldout_frames", "n_real_val_frames", "heldout", "zero_shot", "train",
                   "final_loss", "status", "error", "met": {condition: bool or None}}],
         "summary": [{"condition", "role", "n", "n_failed", "threshold", "n_met",
                      "heldout": {mean, std, min, max}, "zero_shot": {...}, "train": {...}}],
         "thresholds": {condition: AP}}

    APs in % (3D, R40, IoU 0.3; None where not measured); ``std`` is the sample sd (ddof 1).
    """
    thresholds = {str(k): float(v) for k, v in (thresholds or {}).items()}
    out_rows = []
    for r in sorted(rows, key=lambda r: str(r.get("pretrain_id"))):
        aps = {k: _finite(r.get(col)) for k, col in CHECK_COLUMNS.items()}
        loss = list(r.get("history_loss") or [])
        conds = list(r.get("conditions") or [])
        met = {c: (None if c not in thresholds or aps["heldout"] is None
                   else bool(aps["heldout"] >= thresholds[c])) for c in conds}
        out_rows.append({
            "id": r.get("pretrain_id"), "role": r.get("sim_role"), "conditions": conds,
            "trial": r.get("trial"), "fraction": r.get("fraction"),
            "n_sim_frames": r.get("n_sim_frames"), "n_heldout_frames": r.get("n_heldout_frames"),
            "n_real_val_frames": r.get("n_real_val_frames"), **aps,
            "final_loss": _finite(loss[-1]) if loss else None, "status": r.get("status"),
            "error": r.get("error") or "", "met": met})
    names = list(conditions) if conditions is not None else list(
        dict.fromkeys(c for r in out_rows for c in r["conditions"]))
    summary = []
    for cond in names:
        mine = [r for r in out_rows if cond in r["conditions"]]
        if not mine:
            continue
        ok = [r for r in mine if r["status"] != "failed"]
        item = {"condition": cond, "role": mine[0]["role"], "n": len(ok),
                "n_failed": len(mine) - len(ok), "threshold": thresholds.get(cond),
                "n_met": (sum(bool(r["met"].get(cond)) for r in ok) if cond in thresholds
                          else None)}
        for k in CHECK_COLUMNS:
            item[k] = _spread([r[k] for r in ok if r[k] is not None])
        summary.append(item)
    return {"rows": out_rows, "summary": summary, "thresholds": thresholds}
