"""The sweep's plan: which pre-trainings and which fine-tuning runs, with their seeds, subsets and
epochs, and what identifies each of them.

:func:`plan_sweep` is pure: a profile and the real train split's ids in, frozen specs out. The
runs are ordered trial by trial (within a trial: fraction, then condition), so a sweep stopped
early has complete pairs for its first trials. Pre-trainings are deduplicated: one per
(sim dataset role, trial seed) with ``pretrain_per_trial``, otherwise one per role, shared by
every trial (its seed is trial 0's).

:func:`run_key_inputs` and :func:`pretrain_key_inputs` give the JSON-able content that
identifies a run; the caller hashes it (``storage.content_key``) together with the datasets'
content keys and the code version. Settings that do not change a run's result (device, threads,
checkpoint cadence, progress bars, data paths) are left out, so changing them recomputes nothing.

:class:`SweepPlan` is a prepared sweep as the flow runs it (:mod:`sim2radar.experiment.prepare`
builds it): the :class:`SweepContext` every task needs, each :class:`PretrainSpec` and
:class:`RunSpec` with its content key (:class:`PlannedPretrain`, :class:`PlannedRun`) and
``sweep.json``'s document. It is frozen, pickles to Dask workers and round-trips through
``plan.json`` (:meth:`SweepPlan.to_dict`, :meth:`SweepPlan.from_dict`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

from sim2radar.experiment.errors import SettingError
from sim2radar.experiment.profiles import BASELINE, CONDITIONS, ExperimentProfile
from sim2radar.experiment.subsets import real_subset, trial_seed

__all__ = [
    "DatasetRef",
    "PlannedPretrain",
    "PlannedRun",
    "PretrainResult",
    "PretrainSpec",
    "RunSpec",
    "SweepContext",
    "SweepPlan",
    "condition_config",
    "epochs_for",
    "ids_digest",
    "plan_sweep",
    "pretrain_key_inputs",
    "protocol_digest",
    "protocol_settings",
    "run_key_inputs",
    "settings_changes",
]

#: version of :meth:`SweepPlan.to_dict`'s layout (``plan.json``); 1 was the untyped dict plan,
#: 2 had no held-out split and no pre-training check
PLAN_FORMAT = 3
#: profile fields that only say how a sweep is executed or described, not what it measures
#: (the pre-registration's path: its content's digest is part of the settings instead)
EXECUTION_FIELDS = ("name", "description", "detector", "threads_per_run", "concurrent_runs",
                    "preregistration")


@dataclasses.dataclass(frozen=True)
class PretrainSpec:
    """One pre-training run.

    Attributes
    ----------
    condition : str — the (first) condition whose runs load its encoder.
    trial : int or None — the trial it belongs to; None when shared by all trials.
    seed : int — its seed (initial weights, data order); the trial's seed when per trial.
    sim_role : str — dataset role it trains on (``sim``, ``sim-gt``, ``sim-one-material``).
    epochs : int — training epochs on the simulated frames.
    fraction : float or None — with intensity matching, the real-data fraction whose runs load
        it: the sim intensities are matched to that run's own real fine-tuning subset
        (``real_ids``), so each (trial, fraction) has its own pre-training; None otherwise.
    real_ids : tuple of str — that subset's real frame ids (empty without matching).
    holdout_split : str or None — the sim dataset's split held out of the pre-training (its
        held-out sim AP is measured on it); None: it trains on every frame.
    """

    condition: str
    trial: int | None
    seed: int
    sim_role: str
    epochs: int
    fraction: float | None = None
    real_ids: tuple[str, ...] = ()
    holdout_split: str | None = None

    @property
    def name(self) -> str:
        """Readable id, e.g. ``pretrain-sim-t2``, ``pretrain-sim-t2-f0.05`` or
        ``pretrain-sim-shared``."""
        name = f"pretrain-{self.sim_role}-" + ("shared" if self.trial is None
                                               else f"t{self.trial}")
        return name if self.fraction is None else f"{name}-f{self.fraction:g}"

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able fields (e.g. for a Prefect task parameter)."""
        d = dataclasses.asdict(self)
        d["real_ids"] = list(self.real_ids)
        return d


@dataclasses.dataclass(frozen=True)
class RunSpec:
    """One fine-tuning run: a (condition, fraction, trial) cell of the grid.

    Attributes
    ----------
    condition : str — :data:`~sim2radar.experiment.profiles.CONDITIONS` name.
    fraction : float — share of the real train split, in (0, 1].
    trial : int — 0-based trial index.
    seed : int — the trial's seed (:func:`~sim2radar.experiment.subsets.trial_seed`): real
        subset, head initialisation and data order, the same for every condition of the trial.
    n_real : int — real train frames (``len(train_ids)``).
    pretrain : PretrainSpec or None — whose encoder initialises the run (None: from scratch).
    epochs : int — fine-tuning epochs (:func:`epochs_for`; the same for every condition).
    train_ids : tuple of str — the real frames (:func:`~.subsets.real_subset`).
    """

    condition: str
    fraction: float
    trial: int
    seed: int
    n_real: int
    pretrain: PretrainSpec | None
    epochs: int
    train_ids: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        """Readable id, e.g. ``sim-pretrain-f0.25-t3``."""
        return f"{self.condition}-f{self.fraction:g}-t{self.trial}"

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able fields (``train_ids`` as a list, ``pretrain`` as a dict or None)."""
        d = dataclasses.asdict(self)
        d["train_ids"] = list(self.train_ids)
        return d


def epochs_for(n_frames: int, batch_size: int, epochs: int, min_steps: int | None) -> int:
    """Epochs of a run: ``epochs``, raised so that the run makes at least ``min_steps``
    optimiser steps (``ceil(n_frames / batch_size)`` per epoch) when ``min_steps`` is set.

    Depends on the number of frames only, so both conditions of a cell get the same epochs.
    """
    if n_frames < 1:
        raise ValueError("a training run needs at least one frame")
    if batch_size < 1 or epochs < 1:
        raise ValueError(f"batch_size and epochs must be >= 1, got {batch_size}, {epochs}")
    if not min_steps:
        return int(epochs)
    steps_per_epoch = math.ceil(int(n_frames) / int(batch_size))
    return max(int(epochs), math.ceil(int(min_steps) / steps_per_epoch))


def plan_sweep(
    profile: ExperimentProfile,
    train_ids: Sequence[str],
    conditions: Sequence[str] | None = None,
) -> tuple[tuple[PretrainSpec, ...], tuple[RunSpec, ...]]:
    """Every pre-training and fine-tuning run of a sweep.

    Parameters
    ----------
    profile : the sweep's protocol.
    train_ids : the real train split's frame ids.
    conditions : conditions to run (default ``profile.all_conditions``: main conditions, then
        ablations); must include ``baseline``, which every comparison is paired with.

    Returns
    -------
    pretrains : tuple of :class:`PretrainSpec`, each needed by at least one run.
    runs : tuple of :class:`RunSpec`, ``trials x fractions x conditions``, ordered by trial,
        fraction, then condition.
    """
    conds = tuple(profile.all_conditions if conditions is None else conditions)
    for c in conds:
        if c not in CONDITIONS:
            raise ValueError(f"unknown condition {c!r}; known: {sorted(CONDITIONS)}")
    if BASELINE not in conds:
        raise ValueError(f"conditions must include {BASELINE!r}, got {list(conds)}")
    if len(set(conds)) != len(conds):
        raise ValueError(f"duplicate condition in {list(conds)}")
    conds = (BASELINE, *(c for c in conds if c != BASELINE))

    pretrains: dict[tuple[str, int | None, float | None], PretrainSpec] = {}
    # intensity matching fits the sim intensities to each run's own real subset (the 5 % arm
    # must not see the intensities of real frames it does not train on): one pre-training per
    # (trial, fraction); without it, one per trial (or one shared)
    per_subset = bool(profile.intensity_matching)

    def pretrain_for(condition: str, trial: int, fraction: float,
                     ids: tuple[str, ...]) -> PretrainSpec | None:
        role = CONDITIONS[condition].sim_role
        if role is None:
            return None
        per_trial = profile.pretrain_per_trial or per_subset
        key_trial = trial if per_trial else None
        key_fraction = float(fraction) if per_subset else None
        seed = trial_seed(profile.sweep_seed, trial if per_trial else 0)
        key = (role, key_trial, key_fraction)
        if key not in pretrains:
            pretrains[key] = PretrainSpec(condition, key_trial, seed, role,
                                          profile.pretrain_epochs, key_fraction,
                                          ids if per_subset else (),
                                          profile.pretrain_holdout_split)
        return pretrains[key]

    runs: list[RunSpec] = []
    for trial in range(profile.trials):
        seed = trial_seed(profile.sweep_seed, trial)
        for fraction in profile.fractions:
            ids = tuple(real_subset(train_ids, fraction, seed))
            epochs = epochs_for(len(ids), profile.batch_size, profile.finetune_epochs,
                                profile.min_steps)
            for condition in conds:
                runs.append(RunSpec(condition, float(fraction), trial, seed, len(ids),
                                    pretrain_for(condition, trial, fraction, ids), epochs, ids))
    return tuple(pretrains.values()), tuple(runs)


def condition_config(finetune: Mapping[str, Any], condition: str) -> dict[str, Any]:
    """A condition's fine-tuning ``DetectConfig`` dump: the sweep's (``finetune``), with the
    condition's encoder learning-rate share (:attr:`~.profiles.Condition.encoder_lr_scale`) in
    ``optimization.encoder_lr_scale``."""
    scale = float(CONDITIONS[condition].encoder_lr_scale)
    if scale == 1.0:
        return dict(finetune)
    return {**finetune, "optimization": {**dict(finetune["optimization"]),
                                         "encoder_lr_scale": scale}}


def ids_digest(ids: Sequence[str]) -> str:
    """SHA-256 (hex, 20 characters) of frame ids in order (one per line)."""
    return hashlib.sha256("\n".join(ids).encode()).hexdigest()[:20]


def _detector_identity(detector: Mapping[str, Any]) -> dict[str, Any]:
    """The parts of a resolved DetectConfig dump that change a run's result: model,
    augmentation, optimisation (epochs left out: the spec carries the run's own), mixed
    precision (as resolved for the sweep's device: true or false). Name, data paths, seed (the
    spec's), pretrained_encoder (the pretrain's key) and the rest of runtime are left out."""
    det = dict(detector)
    missing = [k for k in ("model", "augmentation", "optimization") if k not in det]
    if missing:
        raise ValueError(f"detector: expected a DetectConfig dump, missing sections {missing}")
    # encoder_lr_scale at its default 1.0 is left out: the runs planned before it existed
    # keep their keys
    optim = {k: v for k, v in dict(det["optimization"]).items()
             if k != "epochs" and not (k == "encoder_lr_scale" and v == 1.0)}
    return {"model": det["model"], "augmentation": det["augmentation"],
            "optimization": optim, "amp": dict(det.get("runtime") or {}).get("amp", False)}


def pretrain_key_inputs(spec: PretrainSpec, detector: Mapping[str, Any],
                        intensity_match: Mapping[str, Any] | None) -> dict[str, Any]:
    """JSON-able content identifying a pre-training (without the sim dataset's key and the code
    version, which the caller adds).

    Parameters
    ----------
    spec : the pre-training.
    detector : resolved pre-training DetectConfig dump (``model_dump(mode="json")``).
    intensity_match : the intensity mapping applied to the sim frames (its dict form), or None.
    """
    out = {"kind": "pretrain", "sim_role": spec.sim_role, "seed": int(spec.seed),
           "epochs": int(spec.epochs), "detector": _detector_identity(detector),
           "intensity_match": None if intensity_match is None else dict(intensity_match)}
    if spec.holdout_split is not None:      # a pre-training on every frame keeps its old key
        out["holdout_split"] = spec.holdout_split
    return out


def run_key_inputs(spec: RunSpec, profile: ExperimentProfile, detector: Mapping[str, Any],
                   pretrain_key: str | None = None) -> dict[str, Any]:
    """JSON-able content identifying a fine-tuning run (without the real dataset's key and the
    code version, which the caller adds).

    Parameters
    ----------
    spec : the run.
    profile : the sweep's profile (evaluation splits and validation cadence are taken from it).
    detector : resolved fine-tuning DetectConfig dump (``model_dump(mode="json")``).
    pretrain_key : content key of the run's pre-training (required exactly when
        ``spec.pretrain`` is set).

    Returns
    -------
    dict — condition, fraction, trial, seed, n_real, epochs, ``train_ids`` digest, pretrain key,
    detector identity and evaluation settings (splits, validation cadence, AP thresholds).
    """
    if (spec.pretrain is None) != (pretrain_key is None):
        raise ValueError(f"{spec.name}: pretrain_key must be given exactly when the run has a "
                         "pre-training")
    return {
        "kind": "finetune", "condition": spec.condition, "fraction": float(spec.fraction),
        "trial": int(spec.trial), "seed": int(spec.seed), "n_real": int(spec.n_real),
        "epochs": int(spec.epochs), "train_ids": ids_digest(spec.train_ids),
        "pretrain": pretrain_key, "detector": _detector_identity(detector),
        "evaluation": {"eval_split": profile.eval_split, "val_split": profile.val_split,
                       "val_every": int(profile.val_every),
                       "max_val_points": int(profile.max_val_points), "ap_thresholds": "devkit"},
    }


def protocol_settings(profile: ExperimentProfile, pretrain_detector: Mapping[str, Any],
                      finetune_detector: Mapping[str, Any]) -> dict[str, Any]:
    """Everything that fixes what a sweep measures, as JSON: the profile's fields without the
    execution-only ones (:data:`EXECUTION_FIELDS`: name, description, the detector file's path,
    threads and concurrency) and both stages' resolved detector identities (model,
    augmentation, optimisation, mixed precision) in place of the detector file's path, so that
    editing the detector YAML a profile points at counts as a change too.

    Parameters
    ----------
    profile : the sweep's profile (after overrides).
    pretrain_detector, finetune_detector : resolved DetectConfig dumps of the two stages.
    """
    fields = {k: v for k, v in profile.model_dump(mode="json").items()
              if k not in EXECUTION_FIELDS}
    return {"profile": fields,
            "detector": {"pretrain": _detector_identity(pretrain_detector),
                         "finetune": _detector_identity(finetune_detector)}}


def protocol_digest(settings: Mapping[str, Any]) -> str:
    """SHA-256 (hex, 20 characters) of :func:`protocol_settings` (canonical JSON)."""
    text = json.dumps(settings, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def settings_changes(old: Mapping[str, Any], new: Mapping[str, Any],
                     prefix: str = "") -> list[str]:
    """The dotted paths whose values differ between two :func:`protocol_settings` documents,
    as ``"path: old -> new"`` lines (for the message that refuses a changed sweep)."""
    out: list[str] = []
    for key in sorted(set(old) | set(new), key=str):
        a, b = old.get(key), new.get(key)
        path = f"{prefix}{key}"
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            out += settings_changes(a, b, path + ".")
        elif a != b:
            out.append(f"{path}: {json.dumps(a, default=str)} -> {json.dumps(b, default=str)}")
    return out


# ---------------------------------------------------------------------------------------------
# A prepared sweep: what the flow runs
# ---------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class DatasetRef:
    """One dataset of a sweep as a task finds it again.

    Attributes
    ----------
    root : str — the folder (OpenPCDet custom layout).
    key : str — its content digest when the sweep was planned
        (:func:`sim2radar.experiment.data.dataset_digest`); a task refuses the folder once its
        digest differs.
    splits : dict — split name -> frame ids, as planned.
    """

    root: str
    key: str
    splits: dict[str, tuple[str, ...]]

    def ids(self, splits: Sequence[str] | None = None) -> list[str]:
        """Frame ids of the given splits (all splits when None), in split order, once each."""
        names = list(self.splits) if splits is None else list(splits)
        return list(dict.fromkeys(i for name in names for i in self.splits.get(name, ())))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DatasetRef:
        return cls(d["root"], d["key"], {k: tuple(v) for k, v in d["splits"].items()})


@dataclasses.dataclass(frozen=True)
class SweepContext:
    """What every task of one sweep needs.

    Attributes
    ----------
    name : str — the sweep's name.
    sweep_dir : str — the sweep folder (checkpoints, runs.parquet, sweep.json, ...).
    store : str — artifact store root (path or URI).
    datasets : dict — role (:data:`~sim2radar.experiment.profiles.ROLES`) -> :class:`DatasetRef`.
    pretrain_config, finetune_config : dict — the stages' resolved ``DetectConfig`` dumps
        (``model_dump(mode="json")``).
    eval_split, val_split : str — the real splits for the test and the learning curves.
    val_every : int — epochs between validation APs (0: none).
    max_val_points : int — at most this many validation APs per run.
    device : str or None — torch device for every run (None: automatic).
    """

    name: str
    sweep_dir: str
    store: str
    datasets: dict[str, DatasetRef]
    pretrain_config: dict[str, Any]
    finetune_config: dict[str, Any]
    eval_split: str = "test"
    val_split: str = "val"
    val_every: int = 0
    max_val_points: int = 12
    device: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SweepContext:
        return cls(**{**d, "datasets": {r: DatasetRef.from_dict(v)
                                        for r, v in d["datasets"].items()}})


@dataclasses.dataclass(frozen=True)
class PlannedPretrain:
    """A pre-training of a prepared sweep.

    Attributes
    ----------
    spec : PretrainSpec.
    key : str — its content key (sim dataset, :func:`pretrain_key_inputs`, code version).
    intensity_match : dict or None — the intensity mapping applied to its sim frames
        (:meth:`~sim2radar.experiment.data.SubsetIntensityMatch.to_dict`), None without.
    conditions : tuple of str — the conditions whose runs load its encoder (``sim-pretrain``
        and ``sim-pretrain-lowlr`` share one).
    """

    spec: PretrainSpec
    key: str
    intensity_match: dict[str, Any] | None = None
    conditions: tuple[str, ...] = ()

    @property
    def id(self) -> str:
        return self.spec.name

    def to_dict(self) -> dict[str, Any]:
        return {**self.spec.to_dict(), "id": self.id, "key": self.key,
                "intensity_match": self.intensity_match, "conditions": list(self.conditions)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PlannedPretrain:
        names = [f.name for f in dataclasses.fields(PretrainSpec)]
        spec = PretrainSpec(**{**{k: d[k] for k in names}, "real_ids": tuple(d["real_ids"])})
        return cls(spec, d["key"], d["intensity_match"], tuple(d["conditions"]))


@dataclasses.dataclass(frozen=True)
class PlannedRun:
    """A fine-tuning run of a prepared sweep.

    Attributes
    ----------
    spec : RunSpec.
    key : str — its content key (real dataset, :func:`run_key_inputs`, code version): the
        key of its ``experiment_runs`` row in the store.
    pretrain_key : str or None — its pre-training's key (None: from scratch).
    """

    spec: RunSpec
    key: str
    pretrain_key: str | None = None

    @property
    def id(self) -> str:
        return self.spec.name

    @property
    def pretrain_id(self) -> str | None:
        return self.spec.pretrain.name if self.spec.pretrain else None

    def to_dict(self) -> dict[str, Any]:
        """The spec's fields with its pre-training named by ``pretrain_id`` and
        ``pretrain_key``, ``id`` and ``key``."""
        fields = {f.name: getattr(self.spec, f.name) for f in dataclasses.fields(RunSpec)
                  if f.name != "pretrain"}
        return {**fields, "train_ids": list(self.spec.train_ids), "id": self.id,
                "key": self.key, "pretrain_id": self.pretrain_id,
                "pretrain_key": self.pretrain_key}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any],
                  pretrains: Mapping[str, PretrainSpec]) -> PlannedRun:
        names = [f.name for f in dataclasses.fields(RunSpec) if f.name != "pretrain"]
        pre = pretrains[d["pretrain_id"]] if d["pretrain_id"] is not None else None
        spec = RunSpec(**{**{k: d[k] for k in names}, "pretrain": pre,
                          "train_ids": tuple(d["train_ids"])})
        return cls(spec, d["key"], d["pretrain_key"])


@dataclasses.dataclass(frozen=True)
class PretrainResult:
    """A finished pre-training, as the fine-tuning runs that load its encoder need it.

    Attributes
    ----------
    key : str — the pre-training's content key.
    checkpoint : str — the checkpoint whose encoder the runs load ('' when it failed).
    n_frames : int — simulated frames it trained on (0 when it failed).
    row : dict — its ``experiment_pretrainings`` row (check, loss curve, status), for the
        sweep's pre-training table; empty when not recorded.
    """

    key: str
    checkpoint: str
    n_frames: int
    row: dict[str, Any] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class SweepPlan:
    """A prepared sweep: every pre-training and run with its key, and what they share.

    Attributes
    ----------
    context : SweepContext — what every task needs.
    pretrains : tuple of PlannedPretrain — in the order the flow submits them.
    runs : tuple of PlannedRun — trial by trial (:func:`plan_sweep`'s order).
    sweep : dict — ``sweep.json``'s document (profile, conditions, datasets, provenance,
        settings; what the dashboard reads).
    concurrent_runs : int — the profile's training runs in flight at once.
    metric : str — the AP column the statistics compare.
    plan_path : str or None — where the plan was written (``<sweep>/plan.json``), the flow's
        parameter: a paper-sized plan exceeds Prefect's 512 KiB limit on flow parameters.
    """

    context: SweepContext
    pretrains: tuple[PlannedPretrain, ...]
    runs: tuple[PlannedRun, ...]
    sweep: dict[str, Any]
    concurrent_runs: int
    metric: str
    plan_path: str | None = None

    @property
    def name(self) -> str:
        return self.context.name

    def runs_after(self, pretrain: PlannedPretrain) -> list[PlannedRun]:
        """The runs that load ``pretrain``'s encoder."""
        return [r for r in self.runs if r.pretrain_id == pretrain.id]

    def find_runs(self, wanted: Sequence[str]) -> list[PlannedRun | PlannedPretrain]:
        """The runs and pre-trainings named in ``wanted`` (run ids such as
        ``sim-pretrain-f0.05-t2``, pre-training ids such as ``pretrain-sim-t2-f0.05``, or
        keys), once each in the order named.

        Raises
        ------
        SettingError — for a name that is no run or pre-training of this sweep, with examples
        (the ``force`` setting: ``--force-run`` on the command line).
        """
        jobs = [*self.runs, *self.pretrains]
        by_name = {j.id: j for j in jobs} | {j.key: j for j in jobs}
        unknown = [w for w in wanted if w not in by_name]
        if unknown:
            example = (f" and pre-training ids like {self.pretrains[0].id!r}"
                       if self.pretrains else "")
            raise SettingError("{force} {value}: no run or pre-training of this sweep has that "
                               "id or key; run ids look like {run}{example} (results.md, the "
                               "dashboard, runs.parquet's run_key, pretrainings.parquet's "
                               "pretrain_key)", value=repr(unknown[0]),
                               run=repr(self.runs[0].id), example=example)
        return list({by_name[w].key: by_name[w] for w in wanted}.values())

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (``plan.json``; :data:`PLAN_FORMAT`), without ``plan_path``."""
        return {"format": PLAN_FORMAT, "context": self.context.to_dict(),
                "pretrains": [p.to_dict() for p in self.pretrains],
                "runs": [r.to_dict() for r in self.runs], "sweep": self.sweep,
                "concurrent_runs": self.concurrent_runs, "metric": self.metric}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], plan_path: str | None = None) -> SweepPlan:
        """Read :meth:`to_dict`'s form; raises ValueError for another format."""
        if d.get("format") != PLAN_FORMAT:
            raise ValueError(f"plan format {d.get('format', 1)}, expected {PLAN_FORMAT}: "
                             "prepare the sweep again")
        pretrains = tuple(PlannedPretrain.from_dict(p) for p in d["pretrains"])
        specs = {p.id: p.spec for p in pretrains}
        return cls(SweepContext.from_dict(d["context"]), pretrains,
                   tuple(PlannedRun.from_dict(r, specs) for r in d["runs"]), dict(d["sweep"]),
                   int(d["concurrent_runs"]), str(d["metric"]), plan_path)
