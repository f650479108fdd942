"""Experiment profiles: how big a sweep is, and how each of its runs trains.

A profile is a YAML file in ``configs/experiment/`` (or anywhere) that :func:`load_profile`
reads into a frozen :class:`ExperimentProfile`. Three are bundled:

``paper``
    The paper's protocol (§6.1): ``configs/detect/pointpillars_door.yaml`` (0.05 m pillars,
    128 x 208 grid, backbone [3, 5, 5]), 20 pre-training and 200 fine-tuning epochs, batch 8,
    AdamW lr 0.003, fractions 5/10/25/50/100 %, 5 trials, baseline vs sim-pretrain. Days of
    CPU time: for a GPU or a cluster.
``demo``
    The same protocol on the small CPU model (``pointpillars_door_cpu_small.yaml``), 3 trials,
    the 5 fractions, fewer epochs with a floor on optimiser steps (``min_steps``). Its numbers
    are not comparable with the paper's; the YAML documents how its values were chosen.
``smoke``
    Seconds on a CPU, for tests: a tiny model (0.2 m pillars, one backbone level), 1-2 epochs,
    2 fractions, 2 trials.

Paths in a profile resolve against the YAML file's folder. Conditions come from
:data:`CONDITIONS` (a registry: an unknown name lists the known ones); ``baseline`` must be one
of them, and the ablations are opt-in.

Departure from the paper, opt-in: ``min_steps`` raises a run's epochs so that it makes at least
that many optimiser steps (:func:`sim2radar.experiment.plan.epochs_for`). The paper trains every
fraction for a fixed 200 epochs, so its 5 % runs (18 frames, 3 steps per epoch) make 600 steps
and its 100 % runs 9,400; a short CPU profile with a fixed epoch count would leave the small
fractions with a few dozen steps, which measures under-training rather than data scarcity. The
raised epochs depend only on the number of real frames, so both conditions of a cell train for
exactly the same number of steps.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from sim2radar.configio import bundled_configs, config_path, read_yaml_mapping

__all__ = [
    "ABLATIONS",
    "BASELINE",
    "CONDITIONS",
    "PAPER_FRACTIONS",
    "ROLES",
    "dataset_roles",
    "Condition",
    "ExperimentProfile",
    "bundled_profiles",
    "default_primary_fractions",
    "load_profile",
]

#: shares of the real train split in the paper's Table 1
PAPER_FRACTIONS = (0.05, 0.10, 0.25, 0.50, 1.00)
BASELINE = "baseline"


@dataclasses.dataclass(frozen=True)
class Condition:
    """One arm of the experiment: its entry in :data:`CONDITIONS` is all a new condition needs
    (the sweep's data roles and command-line flags, report headings and dashboard colours are
    derived from it).

    Attributes
    ----------
    name : str — as in the ``experiment_runs`` table's ``condition`` column.
    sim_role : str or None — dataset role whose frames pre-train the encoder
        (:class:`sim2radar.experiment.data.DomainDataset` roles); None trains from scratch.
    ablation : bool — opt-in (``ablations:`` in a profile) rather than a main condition.
    description : str — one line for reports.
    label : str — table heading (``Sim Pretrain``).
    colour : str — the dashboard's colour (``#rrggbb``).
    geometry : str — the geometry its sim dataset is exported with when the sweep is given
        ``store:NAME`` without one (``reconstructed``, the factory's; ``ground_truth``, the
        ablation without reconstruction errors and the reference radar's positive control).
    encoder_lr_scale : float — the transferred encoder's fine-tuning learning rate as a share
        of the profile's ``lr`` (the head keeps ``lr``; :class:`sim2radar.detect.config.
        OptimConfig`); 1.0 is the paper's protocol.
    """

    name: str
    sim_role: str | None
    ablation: bool
    description: str
    label: str
    colour: str
    geometry: str = "reconstructed"
    encoder_lr_scale: float = 1.0

    @property
    def flag(self) -> str | None:
        """The ``sim2radar sweep`` option that names this condition's sim dataset
        (``--sim``, ``--sim-gt``), None for a condition without pre-training."""
        return f"--{self.sim_role}" if self.sim_role else None


#: the registry of conditions, by name (colours: baseline blue, sim-pretrain red as in the
#: paper's Figure 4, the diagnosis conditions and ablations after). Main conditions (``ablation``
#: False) are listed in a profile's ``conditions``; besides the paper's two, the diagnosis:
#: ``ref-pretrain``, the positive control (pre-trained on the reference radar — the proxy-real
#: data's own device model — run on the sim worlds' ground truth, the same worlds and poses as
#: the sim set: if the protocol can see transfer at all, this must transfer), the top rung of the
#: fidelity ladder sim-pretrain (reconstructed) -> sim-gt-pretrain (ground-truth geometry) ->
#: ref-pretrain (the device model); and ``sim-pretrain-lowlr``, the same pre-training fine-tuned
#: with the encoder at a tenth of the learning rate (discriminative fine-tuning), a second
#: protocol beside the paper's.
CONDITIONS: dict[str, Condition] = {c.name: c for c in (
    Condition(BASELINE, None, False, "random initialisation, trained on real data only",
              "Baseline", "#1f77b4"),
    Condition("sim-pretrain", "sim", False,
              "encoder pre-trained on the factory's simulated radar, then fine-tuned on real",
              "Sim Pretrain", "#d62728"),
    Condition("ref-pretrain", "ref", False,
              "positive control: encoder pre-trained on the reference radar (the proxy-real "
              "data's device model) run on the sim worlds' ground truth, then fine-tuned on "
              "real", "Ref Pretrain (control)", "#ff7f0e", "ground_truth"),
    Condition("sim-pretrain-lowlr", "sim", False,
              "the sim-pretrain encoder fine-tuned at 0.1 x lr (the head at lr): "
              "discriminative fine-tuning, a second protocol beside the paper's",
              "Sim Pretrain, encoder lr x0.1", "#8c564b", encoder_lr_scale=0.1),
    Condition("sim-gt-pretrain", "sim-gt", True,
              "encoder pre-trained on simulated radar of ground-truth geometry and materials "
              "(reconstruction errors removed)", "Sim-GT Pretrain", "#2ca02c", "ground_truth"),
    Condition("sim-one-material-pretrain", "sim-one-material", True,
              "encoder pre-trained on simulated radar whose materials are all one material "
              "(material labelling removed)", "Sim One-Material Pretrain", "#9467bd"),
)}
#: dataset roles of a sweep: ``real`` and each condition's pre-training role, in order
def dataset_roles() -> tuple[str, ...]:
    """The dataset roles a sweep knows, from the registry as it is now: ``real``, then each
    condition's ``sim_role`` in registry order (a condition registered at run time brings its
    role with it)."""
    return ("real", *dict.fromkeys(c.sim_role for c in CONDITIONS.values() if c.sim_role))


#: the dataset roles of the built-in registry (:func:`dataset_roles` follows later additions)
ROLES: tuple[str, ...] = dataset_roles()
ABLATIONS = tuple(n for n, c in CONDITIONS.items() if c.ablation)


#: the largest fraction of the default primary endpoint: the paper's low-data regime
LOW_DATA_FRACTION = 0.25


def default_primary_fractions(fractions: Sequence[float]) -> tuple[float, ...]:
    """The primary endpoint's default fractions: those <= :data:`LOW_DATA_FRACTION` (where the
    paper's effect is largest and scarce real data is the point), or the smallest fraction when
    none is."""
    fr = sorted(float(f) for f in fractions)
    return tuple(f for f in fr if f <= LOW_DATA_FRACTION) or tuple(fr[:1])


def _check_names(names: tuple[str, ...]) -> None:
    for name in names:
        if name not in CONDITIONS:
            raise ValueError(f"unknown condition {name!r}; known: {sorted(CONDITIONS)}")
    if len(set(names)) != len(names):
        raise ValueError(f"duplicate condition in {list(names)}")


class ExperimentProfile(BaseModel):
    """The sweep's protocol: detector, epochs, grid, conditions, evaluation, resources.

    Every default is the paper's protocol (§6.1) where it has one.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: profile name (default: the YAML file's stem)
    name: str = ""
    description: str = ""
    #: detector YAML (``configs/detect/*.yaml``); relative to the profile's folder
    detector: Path
    #: sections of the detector config replaced field by field, e.g. ``{model: {layer_nums:
    #: [1]}}`` (:meth:`sim2radar.detect.DetectConfig.with_updates`); batch size, lr and epochs
    #: come from this profile's own fields, seeds from the plan
    detector_overrides: dict[str, Any] = Field(default_factory=dict)
    #: epochs on the simulated frames (paper: 20)
    pretrain_epochs: int = Field(20, ge=1)
    #: epochs on the real subset, both conditions (paper: 200)
    finetune_epochs: int = Field(200, ge=1)
    #: raise a fine-tuning run's epochs to make at least this many optimiser steps (None: the
    #: paper's fixed epochs); a departure from the paper, see the module docstring
    min_steps: int | None = Field(None, ge=1)
    #: frames per optimiser step, pre-training and fine-tuning (paper: 8)
    batch_size: int = Field(8, ge=1)
    #: AdamW peak learning rate of the one-cycle schedule (paper: 0.003)
    lr: float = Field(0.003, gt=0)
    #: shares of the real train split, increasing, in (0, 1]
    fractions: tuple[float, ...] = PAPER_FRACTIONS
    #: trials per (condition, fraction); trial t's seed fixes its real subset, the head's
    #: initialisation and the data order, shared by all conditions
    trials: int = Field(5, ge=1)
    #: main conditions (must include ``baseline``)
    conditions: tuple[str, ...] = (BASELINE, "sim-pretrain")
    #: opt-in ablation conditions (``sim-gt-pretrain``, ``sim-one-material-pretrain``)
    ablations: tuple[str, ...] = ()
    #: True: one pre-training per trial seed, shared by that trial's fractions; False: one
    #: pre-training per sim dataset, shared by all trials
    pretrain_per_trial: bool = True
    #: split of every pre-training dataset held out of pre-training (the export's splits are
    #: world-disjoint): each pre-training is checked on it (held-out sim AP) and zero-shot on the
    #: real ``val_split`` (:mod:`sim2radar.experiment.learnability`). None pre-trains on every
    #: frame, as the paper does, and leaves the held-out sim AP unmeasured
    pretrain_holdout_split: str | None = "val"
    #: pre-registered learnability thresholds: condition -> the held-out sim AP [%] its
    #: pre-trainings are expected to reach. The report states whether each met it; no run is
    #: selected or dropped by it
    learnability_thresholds: dict[str, float] = Field(default_factory=dict)
    #: the primary endpoint's fractions: the mean paired difference pooled over them (per trial,
    #: then across trials) is the sweep's pre-registered answer; per-fraction comparisons are
    #: secondary. None: the fractions <= 25 % (the paper's low-data regime, where its effect is
    #: largest and scarce data is the point), or the smallest fraction when none is
    primary_fractions: tuple[float, ...] | None = None
    #: the condition whose pooled difference to the baseline is the primary endpoint (the other
    #: conditions' pooled differences are reported beside it as diagnostics)
    primary_condition: str = "sim-pretrain"
    #: the sweep refuses to run without its pre-registration file (question, conditions,
    #: endpoints, trials, decision rules, written before the first run)
    preregistered: bool = False
    #: the pre-registration (Markdown), relative to the profile's folder; the sweep records its
    #: SHA-256 with the settings (an edit after the first run is refused like any other change)
    #: and copies it into the sweep folder
    preregistration: Path | None = None
    #: map simulated intensities onto the real ones (log-space histogram matching, §6.1),
    #: fitted on each run's own real fine-tuning subset (one pre-training per trial and
    #: fraction)
    intensity_matching: bool = True
    #: epochs between validation APs (3D, R40, IoU 0.3) on ``val_split``; 0 = none. Learning
    #: curves only: the last epoch is tested, as in the paper
    val_every: int = Field(0, ge=0)
    #: at most this many validation APs per run: a run with many short epochs (a small fraction
    #: raised to ``min_steps``) validates every ``ceil(epochs / max_val_points)`` epochs instead
    max_val_points: int = Field(12, ge=1)
    train_split: str = "train"
    val_split: str = "val"
    eval_split: str = "test"
    #: seed of the whole sweep; trial seeds derive from it (:func:`~.subsets.trial_seed`)
    sweep_seed: int = Field(0, ge=0)
    #: torch intra-op threads of one training run on CPU (None: torch's default)
    threads_per_run: int | None = Field(None, ge=1)
    #: training runs in flight at once
    concurrent_runs: int = Field(1, ge=1)

    @field_validator("fractions")
    @classmethod
    def _fractions(cls, v: tuple[float, ...]) -> tuple[float, ...]:
        if not v:
            raise ValueError("needs at least one fraction")
        if any(not 0.0 < f <= 1.0 for f in v):
            raise ValueError(f"fractions must lie in (0, 1], got {list(v)}")
        if any(b <= a for a, b in zip(v, v[1:], strict=False)):
            raise ValueError(f"fractions must be strictly increasing, got {list(v)}")
        return v

    @field_validator("conditions")
    @classmethod
    def _main(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        _check_names(v)
        if BASELINE not in v:
            raise ValueError(f"must include {BASELINE!r} (every comparison is paired with it), "
                             f"got {list(v)}")
        abl = [c for c in v if CONDITIONS[c].ablation]
        if abl:
            raise ValueError(f"{abl} are ablations: list them under 'ablations'")
        return v

    @field_validator("ablations")
    @classmethod
    def _ablations(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        _check_names(v)
        main = [c for c in v if not CONDITIONS[c].ablation]
        if main:
            raise ValueError(f"{main} are main conditions; ablations are {list(ABLATIONS)}")
        return v

    @field_validator("learnability_thresholds")
    @classmethod
    def _thresholds(cls, v: dict[str, float]) -> dict[str, float]:
        for name, ap in v.items():
            if name not in CONDITIONS or CONDITIONS[name].sim_role is None:
                raise ValueError(f"{name!r} is no pre-trained condition; known: "
                                 f"{sorted(c for c, x in CONDITIONS.items() if x.sim_role)}")
            if not 0.0 <= float(ap) <= 100.0:
                raise ValueError(f"{name}: a threshold is an AP in [0, 100] %, got {ap}")
        return v

    @field_validator("primary_condition")
    @classmethod
    def _primary_condition(cls, v: str) -> str:
        if v not in CONDITIONS or v == BASELINE:
            raise ValueError(f"{v!r}: the primary condition is a registered condition other "
                             f"than {BASELINE!r}; known: {sorted(CONDITIONS)}")
        return v

    @model_validator(mode="after")
    def _primary(self) -> ExperimentProfile:
        if self.primary_fractions is not None:
            if not self.primary_fractions:
                raise ValueError("primary_fractions: give at least one fraction, or null for "
                                 "the fractions <= 25 %")
            off = [f for f in self.primary_fractions if f not in self.fractions]
            if off:
                raise ValueError(f"primary_fractions {off} are not among fractions "
                                 f"{list(self.fractions)}")
        if self.preregistered and self.preregistration is None:
            raise ValueError("preregistered: true needs 'preregistration' (the file written "
                             "before the first run)")
        return self

    @property
    def primary(self) -> tuple[float, ...]:
        """The primary endpoint's fractions (:attr:`primary_fractions`, or
        :func:`default_primary_fractions`)."""
        if self.primary_fractions is not None:
            return tuple(self.primary_fractions)
        return default_primary_fractions(self.fractions)

    @field_validator("detector_overrides")
    @classmethod
    def _sections(cls, v: dict[str, Any]) -> dict[str, Any]:
        from sim2radar.detect.config import DetectConfig

        unknown = sorted(set(v) - set(DetectConfig.model_fields))
        if unknown:
            raise ValueError(f"unknown detector section(s) {unknown}; known: "
                             f"{sorted(DetectConfig.model_fields)}")
        return v

    @property
    def all_conditions(self) -> tuple[str, ...]:
        """Main conditions, then ablations (``baseline`` first when listed first)."""
        return self.conditions + self.ablations

    def detector_config(self, stage: Literal["pretrain", "finetune"] = "finetune"):
        """The resolved :class:`~sim2radar.detect.DetectConfig` of one stage's runs: the
        detector YAML (read here) with ``detector_overrides``, this profile's batch size, lr
        and the stage's epochs, ``runtime.num_threads = threads_per_run`` and no progress bar.

        A fine-tuning run may train for more epochs than ``finetune_epochs`` when ``min_steps``
        is set (:func:`~sim2radar.experiment.plan.epochs_for`); its planned epochs are passed to
        :func:`sim2radar.detect.train.train` explicitly.

        Raises
        ------
        FileNotFoundError, ValueError — naming the detector file and the field at fault.
        """
        from sim2radar.detect.config import load_config

        if stage not in ("pretrain", "finetune"):
            raise ValueError(f"stage must be 'pretrain' or 'finetune', got {stage!r}")
        cfg = load_config(self.detector)
        epochs = self.pretrain_epochs if stage == "pretrain" else self.finetune_epochs
        try:
            cfg = cfg.with_updates(**self.detector_overrides)
        except ValidationError as exc:
            raise ValueError(f"profile {self.name!r}: detector_overrides do not fit "
                             f"{self.detector}:\n{_describe(exc)}") from None
        runtime = {"progress": False}
        if self.threads_per_run is not None:
            runtime["num_threads"] = self.threads_per_run
        return cfg.with_updates(
            optimization={"batch_size": self.batch_size, "lr": self.lr, "epochs": epochs},
            runtime=runtime,
        )


def _describe(exc: ValidationError) -> str:
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
        lines.append(f"  field '{loc}': {err['msg']}")
    return "\n".join(lines)


def bundled_profiles() -> list[str]:
    """Names of the bundled profiles (package data ``sim2radar.configs``, folder ``experiment``)."""
    return bundled_configs("experiment")


def load_profile(name_or_path: str | Path) -> ExperimentProfile:
    """Read a profile: a bundled name (``paper``, ``demo``, ``smoke``) or a YAML path.

    ``detector`` resolves against the YAML's folder, and the detector config is built once
    (with ``detector_overrides``) so that a bad override fails here, not in the first run.

    Raises
    ------
    FileNotFoundError — no such file or bundled profile (the message lists the bundled ones).
    ValueError — naming the file and each field at fault.
    """
    path = config_path(name_or_path, "experiment", what="experiment profile")
    raw = read_yaml_mapping(path, what="experiment profile", missing_error=FileNotFoundError)
    raw.setdefault("name", path.stem)
    try:
        profile = ExperimentProfile.model_validate(raw)
    except ValidationError as exc:
        raise ValueError(f"{path}: invalid experiment profile:\n{_describe(exc)}") from None
    det = profile.detector.expanduser()
    if not det.is_absolute():
        det = (path.resolve().parent / det).resolve()
    profile = profile.model_copy(update={"detector": det})
    if profile.preregistration is not None:
        pre = profile.preregistration.expanduser()
        if not pre.is_absolute():
            pre = (path.resolve().parent / pre).resolve()
        profile = profile.model_copy(update={"preregistration": pre})
    from sim2radar.detect.config import load_config

    try:
        load_config(det)
    except (FileNotFoundError, ValueError) as exc:
        raise type(exc)(f"{path}: field 'detector': {exc}") from None
    try:
        profile.detector_config("finetune")
    except ValueError as exc:
        raise ValueError(f"{path}: field 'detector_overrides': {exc}") from None
    return profile
