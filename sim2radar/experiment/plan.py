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
``sweep.json``'s document (:class:`~sim2radar.experiment.documents.SweepDocument`). The records
are frozen pydantic models: they pickle to Dask workers and round-trip through ``plan.json``
(``plan.model_dump(mode="json")``, ``SweepPlan.model_validate(doc)``) in the layout of
:data:`PLAN_FORMAT` 3, so plans written before they were pydantic models still load.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict, Field, model_serializer, model_validator

from sim2radar.experiment.documents import SweepDocument
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

#: version of ``plan.json``'s layout (:class:`SweepPlan`'s JSON dump); 1 was the untyped dict
#: plan, 2 had no held-out split and no pre-training check
PLAN_FORMAT = 3
#: profile fields that only say how a sweep is executed or described, not what it measures
#: (the pre-registration's path: its content's digest is part of the settings instead)
EXECUTION_FIELDS = ("name", "description", "detector", "threads_per_run", "concurrent_runs",
                    "preregistration")


if TYPE_CHECKING:
    from sim2radar.detect.config import DetectConfig


class _LazyDetectConfig:
    """:class:`~sim2radar.detect.config.DetectConfig` as a field type, imported when a model
    holding it is first used (``defer_build``): importing ``sim2radar.detect`` loads torch, which
    ``sim2radar --help`` and the store's schemas must not pay for."""

    @classmethod
    def __get_pydantic_core_schema__(cls, source: Any, handler: Any) -> Any:
        from sim2radar.detect.config import DetectConfig

        return handler.generate_schema(DetectConfig)


class _Record(BaseModel):
    """A frozen plan record (validated on construction; pickles; equal by value)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class PretrainSpec(_Record):
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


class RunSpec(_Record):
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
            pretrains[key] = PretrainSpec(
                condition=condition, trial=key_trial, seed=seed, sim_role=role,
                epochs=profile.pretrain_epochs, fraction=key_fraction,
                real_ids=ids if per_subset else (), holdout_split=profile.pretrain_holdout_split)
        return pretrains[key]

    runs: list[RunSpec] = []
    for trial in range(profile.trials):
        seed = trial_seed(profile.sweep_seed, trial)
        for fraction in profile.fractions:
            ids = tuple(real_subset(train_ids, fraction, seed))
            epochs = epochs_for(len(ids), profile.batch_size, profile.finetune_epochs,
                                profile.min_steps)
            for condition in conds:
                runs.append(RunSpec(condition=condition, fraction=float(fraction), trial=trial,
                                    seed=seed, n_real=len(ids),
                                    pretrain=pretrain_for(condition, trial, fraction, ids),
                                    epochs=epochs, train_ids=ids))
    return tuple(pretrains.values()), tuple(runs)


def condition_config(finetune: DetectConfig, condition: str) -> DetectConfig:
    """A condition's fine-tuning ``DetectConfig``: the sweep's (``finetune``), with the
    condition's encoder learning-rate share (:attr:`~.profiles.Condition.encoder_lr_scale`) in
    ``optimization.encoder_lr_scale``."""
    scale = float(CONDITIONS[condition].encoder_lr_scale)
    if scale == 1.0:
        return finetune
    return finetune.with_updates(optimization={"encoder_lr_scale": scale})


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
class DatasetRef(_Record):
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


class SweepContext(_Record):
    """What every task of one sweep needs.

    Attributes
    ----------
    name : str — the sweep's name.
    sweep_dir : str — the sweep folder (checkpoints, runs.parquet, sweep.json, ...).
    store : str — artifact store root (path or URI).
    datasets : dict — role (:data:`~sim2radar.experiment.profiles.ROLES`) -> :class:`DatasetRef`.
    pretrain_config, finetune_config : DetectConfig — the stages' resolved configs (in
        ``plan.json`` as their ``model_dump(mode="json")``).
    eval_split, val_split : str — the real splits for the test and the learning curves.
    val_every : int — epochs between validation APs (0: none).
    max_val_points : int — at most this many validation APs per run.
    device : str or None — torch device for every run (None: automatic).
    """

    name: str
    sweep_dir: str
    store: str
    datasets: dict[str, DatasetRef]
    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    pretrain_config: _LazyDetectConfig
    finetune_config: _LazyDetectConfig
    eval_split: str = "test"
    val_split: str = "val"
    val_every: int = 0
    max_val_points: int = 12
    device: str | None = None


class PlannedPretrain(_Record):
    """A pre-training of a prepared sweep.

    Attributes
    ----------
    spec : PretrainSpec.
    key : str — its content key (sim dataset, :func:`pretrain_key_inputs`, code version).
    intensity_match : dict or None — the intensity mapping applied to its sim frames
        (:meth:`~sim2radar.experiment.data.SubsetIntensityMatch.to_dict`), None without.
    conditions : tuple of str — the conditions whose runs load its encoder (``sim-pretrain``
        and ``sim-pretrain-lowlr`` share one).

    In ``plan.json`` the spec's fields sit beside ``id``, ``key``, ``intensity_match`` and
    ``conditions`` (one flat object).
    """

    spec: PretrainSpec
    key: str
    intensity_match: dict[str, Any] | None = None
    conditions: tuple[str, ...] = ()

    @property
    def id(self) -> str:
        return self.spec.name

    @model_validator(mode="before")
    @classmethod
    def _unflatten(cls, d: Any) -> Any:
        if isinstance(d, Mapping) and "spec" not in d:     # plan.json's flat object
            return {"spec": {k: d[k] for k in PretrainSpec.model_fields if k in d},
                    **{k: d[k] for k in ("key", "intensity_match", "conditions") if k in d}}
        return d

    @model_serializer(mode="wrap")
    def _flatten(self, handler) -> dict[str, Any]:
        d = handler(self)
        return {**d.pop("spec"), "id": self.id, **d}


class PlannedRun(_Record):
    """A fine-tuning run of a prepared sweep.

    Attributes
    ----------
    spec : RunSpec.
    key : str — its content key (real dataset, :func:`run_key_inputs`, code version): the
        key of its ``experiment_runs`` row in the store.
    pretrain_key : str or None — its pre-training's key (None: from scratch).

    In ``plan.json`` the spec's fields sit beside ``id``, ``key``, ``pretrain_id`` and
    ``pretrain_key``; its pre-training is named by ``pretrain_id`` (:class:`SweepPlan` finds
    the spec among the plan's pre-trainings).
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

    @model_validator(mode="before")
    @classmethod
    def _unflatten(cls, d: Any) -> Any:
        if isinstance(d, Mapping) and "spec" not in d:     # plan.json's flat object
            spec = {k: d[k] for k in RunSpec.model_fields if k in d}
            return {"spec": spec, "key": d["key"], "pretrain_key": d.get("pretrain_key")}
        return d

    @model_serializer(mode="wrap")
    def _flatten(self, handler) -> dict[str, Any]:
        d = handler(self)
        spec = {k: v for k, v in d.pop("spec").items() if k != "pretrain"}
        return {**spec, "id": self.id, "key": self.key, "pretrain_id": self.pretrain_id,
                "pretrain_key": self.pretrain_key}


class PretrainResult(_Record):
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
    row: dict[str, Any] = Field(default_factory=dict)


class SweepPlan(_Record):
    """A prepared sweep: every pre-training and run with its key, and what they share.

    Attributes
    ----------
    context : SweepContext — what every task needs.
    pretrains : tuple of PlannedPretrain — in the order the flow submits them.
    runs : tuple of PlannedRun — trial by trial (:func:`plan_sweep`'s order).
    sweep : SweepDocument — ``sweep.json``'s document (profile, conditions, datasets,
        provenance, settings; what the dashboard reads).
    concurrent_runs : int — the profile's training runs in flight at once.
    metric : str — the AP column the statistics compare.
    plan_path : str or None — where the plan was written (``<sweep>/plan.json``), the flow's
        parameter: a paper-sized plan exceeds Prefect's 512 KiB limit on flow parameters.
        Not part of the JSON form.

    Its JSON form (``model_dump(mode="json")``, ``plan.json``) leads with ``"format":``
    :data:`PLAN_FORMAT`; ``model_validate`` refuses another format.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    context: SweepContext
    pretrains: tuple[PlannedPretrain, ...]
    runs: tuple[PlannedRun, ...]
    sweep: SweepDocument
    concurrent_runs: int
    metric: str
    plan_path: str | None = Field(default=None, exclude=True)

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

    @model_validator(mode="before")
    @classmethod
    def _read_format(cls, d: Any) -> Any:
        """plan.json: its format checked, each run's pre-training found by ``pretrain_id``."""
        if not isinstance(d, Mapping) or not ("format" in d or any(
                isinstance(r, Mapping) for r in d.get("runs", ()))):
            return d                            # built from records, not read from JSON
        if d.get("format") != PLAN_FORMAT:
            raise ValueError(f"plan format {d.get('format', 1)}, expected {PLAN_FORMAT}: "
                             "prepare the sweep again")
        specs = {}
        for p in d["pretrains"]:
            p = p if isinstance(p, PlannedPretrain) else PlannedPretrain.model_validate(p)
            specs[p.id] = p.spec
        runs = [r if not isinstance(r, Mapping) or "spec" in r else
                {**r, "pretrain": None if r.get("pretrain_id") is None
                 else specs[r["pretrain_id"]]} for r in d["runs"]]
        return {k: v for k, v in d.items() if k != "format"} | {"runs": runs}

    @model_serializer(mode="wrap")
    def _write_format(self, handler) -> dict[str, Any]:
        return {"format": PLAN_FORMAT, **handler(self)}
