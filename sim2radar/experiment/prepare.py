"""Preparing a sweep: from a profile and its opened datasets to the
:class:`~sim2radar.experiment.plan.SweepPlan` the flow runs.

    datasets = {"sim": "data/sim", "real": "store:reference"}
    setup = setup_sweep("demo", datasets, overrides={"trials": 3})
    domains = open_datasets(datasets, setup.roles, export)   # export: store:NAME -> a folder
    plan = build_plan(setup, domains, name="demo", key_of=..., ...)

The conditions and their dataset roles come from the condition registry
(:data:`~sim2radar.experiment.profiles.CONDITIONS`): a new condition is one registry entry.
Every frame a sweep will read is loaded and checked (and a simulated dataset holding a real
evaluation frame refused) before the plan exists. A sweep's settings are fixed by its first
preparation (:func:`settings_fixed_at`).

The other phases: what a prepared sweep would cost is :func:`sim2radar.experiment.cost.sweep_cost`;
its statistics, report and dashboard at the end are :mod:`sim2radar.experiment.finish`.

What stays with the caller (``tasks/experiment.py``): exporting ``store:NAME`` datasets, reading
and writing the sweep folder's files, and hashing key inputs into content keys — the
``key_of(kind, inputs, key_inputs)`` function :func:`build_plan` is given, which adds the code
version (``storage.content_key``).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sim2radar.experiment.documents import SweepDocument
from sim2radar.experiment.errors import SettingError, dataset_setting
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.plan import (
    DatasetRef,
    PlannedPretrain,
    PlannedRun,
    SweepContext,
    SweepPlan,
    condition_config,
    plan_sweep,
    pretrain_key_inputs,
    protocol_digest,
    protocol_settings,
    run_key_inputs,
    settings_changes,
)
from sim2radar.experiment.profiles import ABLATIONS, CONDITIONS, ExperimentProfile, dataset_roles

__all__ = [
    "GROUND_TRUTH_ROLES",
    "PREREGISTRATION_FILE",
    "KeyFn",
    "PreregistrationMissing",
    "SweepSettingsChanged",
    "SweepSetup",
    "build_plan",
    "check_sweep_name",
    "open_datasets",
    "preregistration",
    "resolve_profile",
    "settings_fixed_at",
    "setup_sweep",
    "stage_configs",
    "sweep_conditions",
]

#: the pre-registration's copy in a sweep folder
PREREGISTRATION_FILE = SweepFolder.PREREGISTRATION
#: ``key_of(kind, inputs, key_inputs) -> content key``: ``kind`` is ``"pretrain"`` or
#: ``"finetune"``, ``inputs`` the dataset digests by name, ``key_inputs`` what
#: :func:`~.plan.pretrain_key_inputs` / :func:`~.plan.run_key_inputs` give
KeyFn = Callable[[str, Mapping[str, str], Mapping[str, Any]], str]


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def check_sweep_name(name: str) -> None:
    """A sweep name is one safe path component (its folder is ``<out>/<name>``): letters,
    digits, '-', '_' and '.', not starting with '.' (so never ``.`` or ``..``)."""
    if not name or name.startswith(".") or not all(c.isalnum() or c in "-_." for c in name):
        raise SettingError("{name} {value}: a sweep name is one folder name under {out} — use "
                           "letters, digits, '-', '_' or '.', not starting with '.'",
                           value=repr(name))


def resolve_profile(profile: str | os.PathLike | ExperimentProfile,
                    overrides: Mapping[str, Any] | None = None) -> ExperimentProfile:
    """A profile (bundled name, YAML path or object) with ``overrides`` applied and validated;
    raises ValueError naming the field."""
    from sim2radar.experiment.profiles import load_profile

    prof = profile if isinstance(profile, ExperimentProfile) else load_profile(profile)
    if overrides:
        try:
            prof = ExperimentProfile.model_validate({**prof.model_dump(), **overrides})
        except Exception as exc:  # pydantic's message names the field
            raise ValueError(f"profile {prof.name!r} overrides: {exc}") from None
    return prof


def _resolve_precision(cfg, device: str | None, table: str | os.PathLike | None,
                       probe: bool, known: Mapping[str, Any] | None = None
                       ) -> tuple[Any, dict[str, Any]]:
    """``runtime.amp: auto`` decided once, for the sweep's device, on the machine that plans
    it, by measurement (:func:`sim2radar.detect.precision.decide_precision`: a timed probe of
    this model, recorded in ``table`` and reused): every run of the sweep trains in the same
    precision wherever it executes, and the choice is part of the runs' keys and the sweep's
    settings. Returns the config with ``amp`` true/false and the decision (for sweep.json)."""
    from sim2radar.detect.precision import decide_precision
    from sim2radar.hardware import torch_device

    dev = torch_device(device or cfg.runtime.device)
    decision = decide_precision(cfg, dev, table=table, probe=probe,
                                known=dict(known) if known else None)
    return cfg.with_updates(runtime={"amp": decision.amp}), decision.to_dict()


def stage_configs(profile: ExperimentProfile, device: str | None, *,
                  precision_table: str | os.PathLike | None = None,
                  probe: bool = True, known: Mapping[str, Any] | None = None
                  ) -> tuple[tuple[Any, Any], dict[str, Any]]:
    """The pre-training and fine-tuning ``DetectConfig`` of the profile, mixed precision
    resolved for ``device`` (the device itself is not set: :func:`build_plan` does), and the
    precision decisions by stage (``known``: the ones this sweep recorded before, by stage)."""
    known = known or {}
    pre, pre_dec = _resolve_precision(profile.detector_config("pretrain"), device,
                                      precision_table, probe, known.get("pretrain"))
    ft, ft_dec = _resolve_precision(profile.detector_config("finetune"), device,
                                    precision_table, probe, known.get("finetune"))
    return (pre, ft), {"pretrain": pre_dec, "finetune": ft_dec}


def sweep_conditions(profile: ExperimentProfile, ablations: bool,
                     datasets: Mapping[str, Any]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The sweep's conditions (the profile's, plus every ablation with ``ablations``) and the
    dataset roles they need, in :data:`~.profiles.ROLES` order.

    ``datasets`` : role -> source (None or absent: not given).

    Raises
    ------
    ValueError — a role that is not one of ROLES. SettingError — conditions whose datasets
    were not given, naming those datasets' settings (``{dataset:sim-gt}``: a command line
    spells it as its option).
    """
    roles = dataset_roles()
    unknown = sorted(set(datasets) - set(roles))
    if unknown:
        raise ValueError(f"unknown dataset role(s) {unknown}; known: {list(roles)}")
    conditions = list(profile.all_conditions)
    if ablations:
        conditions += [c for c in ABLATIONS if c not in conditions]
    needed = {"real"} | {CONDITIONS[c].sim_role for c in conditions if CONDITIONS[c].sim_role}
    missing = [r for r in roles if r in needed and datasets.get(r) is None]
    if missing:
        raise SettingError("conditions {conditions} need the dataset(s) "
                           + ", ".join(f"{{{dataset_setting(r)}}}" for r in missing),
                           conditions=", ".join(c for c in conditions
                                                if CONDITIONS[c].sim_role in missing))
    return tuple(conditions), tuple(r for r in roles if r in needed)


#: roles whose ``store:NAME`` dataset is exported with the worlds' true geometry by default: the
#: real role (measured-like data) and the conditions registered with ``geometry="ground_truth"``
#: (the ablation without reconstruction errors); the others with the reconstructed geometry
GROUND_TRUTH_ROLES = ("real", *(c.sim_role for c in CONDITIONS.values()
                                if c.sim_role and c.geometry == "ground_truth"))


def open_datasets(sources: Mapping[str, Any], roles: Sequence[str],
                  export: Callable[[str, str, str], str | os.PathLike]) -> dict[str, Any]:
    """Open each role's dataset (:func:`~sim2radar.experiment.data.open_domain`): a folder, or
    ``store:NAME[:geometry]``, which ``export(role, name, geometry)`` writes to a folder first
    (geometry by default ``ground_truth`` for :data:`GROUND_TRUTH_ROLES`, else
    ``reconstructed``).

    Raises
    ------
    FileNotFoundError — a folder that does not exist; DatasetError — one that is no dataset.
    """
    from sim2radar.experiment.data import open_domain

    out = {}
    for role in roles:
        text = os.fspath(sources[role])
        if text.startswith("store:"):
            name, _, geometry = text.removeprefix("store:").partition(":")
            geometry = geometry or ("ground_truth" if role in GROUND_TRUTH_ROLES
                                    else "reconstructed")
            text = os.fspath(export(role, name, geometry))
        elif not os.path.isdir(text):
            raise FileNotFoundError(f"{role} dataset {text!r}: no such folder (give an "
                                    "OpenPCDet dataset folder, or store:NAME for a dataset in "
                                    "the store)")
        out[role] = open_domain(text, role)
    return out


@dataclasses.dataclass(frozen=True)
class SweepSetup:
    """A sweep's protocol, before its datasets are opened.

    Attributes
    ----------
    profile : ExperimentProfile — after overrides.
    conditions : tuple of str — the conditions to run (:func:`sweep_conditions`).
    roles : tuple of str — the dataset roles they need, in ROLES order.
    configs : (DetectConfig, DetectConfig) — pre-training and fine-tuning
        (:func:`stage_configs`).
    settings : dict — :func:`~.plan.protocol_settings`: what fixes what the sweep measures
        (with the pre-registration's SHA-256 when the profile names one).
    device : str or None — torch device of every run (None: automatic).
    preregistration : dict or None — :func:`preregistration`.
    """

    profile: ExperimentProfile
    conditions: tuple[str, ...]
    roles: tuple[str, ...]
    configs: tuple[Any, Any]
    settings: dict[str, Any]
    device: str | None = None
    preregistration: dict[str, Any] | None = None
    precision: dict[str, Any] = dataclasses.field(default_factory=dict)


def setup_sweep(profile: str | os.PathLike | ExperimentProfile, datasets: Mapping[str, Any], *,
                ablations: bool = False, overrides: Mapping[str, Any] | None = None,
                device: str | None = None, precision_table: str | os.PathLike | None = None,
                probe: bool = True, known_precision: Mapping[str, Any] | None = None
                ) -> SweepSetup:
    """:func:`resolve_profile`, :func:`sweep_conditions` (``datasets``: role -> source),
    :func:`stage_configs` (``precision_table``, ``probe``, ``known_precision``: how ``amp:
    auto`` is decided) and the protocol settings; raises ValueError / FileNotFoundError naming
    the profile, field or missing dataset."""
    prof = resolve_profile(profile, overrides)
    conditions, roles = sweep_conditions(prof, ablations, datasets)
    configs, precision = stage_configs(prof, device, precision_table=precision_table,
                                       probe=probe, known=known_precision)
    settings = protocol_settings(prof, *(c.model_dump(mode="json") for c in configs))
    prereg = preregistration(prof)
    if prereg is not None:
        settings["preregistration"] = {"sha256": prereg["sha256"]}
    return SweepSetup(prof, conditions, roles, configs, settings, device, prereg, precision)


class PreregistrationMissing(SettingError):
    """A profile that declares ``preregistered: true`` has no readable pre-registration."""


def preregistration(profile: ExperimentProfile) -> dict[str, Any] | None:
    """The profile's pre-registration: ``{"path", "sha256", "text"}``, or None when it names
    none.

    Raises
    ------
    PreregistrationMissing — ``preregistered: true`` and the file is absent or empty (the
    sweep refuses to run: a pre-registered study is written down before its first run).
    """
    import hashlib

    path = profile.preregistration
    if path is None:
        return None
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        if not profile.preregistered:
            return None
        raise PreregistrationMissing(
            "profile {profile} is pre-registered but its pre-registration {path} cannot be "
            "read ({reason}). Write it (question, conditions, endpoints, trials, decision "
            "rules, what would count as transfer) and commit it before the first run, or give "
            "its path with {preregistration}.", profile=repr(profile.name), path=str(path),
            reason=str(exc.strerror or exc)) from None
    if profile.preregistered and not text.strip():
        raise PreregistrationMissing("{path}: the pre-registration of profile {profile} is "
                                     "empty", path=str(path), profile=repr(profile.name))
    return {"path": str(path), "sha256": hashlib.sha256(text.encode()).hexdigest(),
            "text": text}


class SweepSettingsChanged(SettingError):
    """A sweep folder's settings were fixed by its first preparation and now differ."""


def settings_fixed_at(old: SweepDocument | Any, settings: Mapping[str, Any], *,
                      name: str, sweep_dir: str | os.PathLike) -> str:
    """When the settings of sweep ``name`` were fixed: now for a new sweep (``old``, its
    earlier ``sweep.json``, None), the first preparation's time otherwise.

    A sweep's results must come from one set of settings, fixed before its first run: a
    profile edited after some runs finished would mix two protocols in one table (and invites
    tuning the protocol toward the answer). A folder written before settings were recorded
    adopts the current ones.

    Parameters
    ----------
    old : the folder's :class:`~.documents.SweepDocument`
        (:meth:`~.folder.SweepFolder.read_sweep_document`, which refuses a damaged file), or
        None.
    settings : :func:`~.plan.protocol_settings` of the sweep being prepared.

    Raises
    ------
    SweepSettingsChanged — the settings differ from ``old``'s, listing what changed.
    """
    if old is None:
        return _now()
    if old.settings is None:                     # a folder from before settings existed
        return str(old.created_at or _now())
    if protocol_digest(old.settings) == protocol_digest(settings):
        return str(old.settings_fixed_at or old.created_at or _now())
    changes = settings_changes(old.settings, settings)
    shown = "\n  ".join(changes[:12]) + (f"\n  ... and {len(changes) - 12} more"
                                          if len(changes) > 12 else "")
    raise SweepSettingsChanged(
        "sweep {sweep} ({folder}) was created with other settings (fixed at {fixed_at}, digest "
        "{digest}); what changed:\n  {shown}\nOne sweep's runs all use the settings fixed "
        "before its first run: start a new sweep name ({name}) for the new settings, or delete "
        "the folder to discard the old sweep.", sweep=repr(name), folder=str(sweep_dir),
        fixed_at=str(old.settings_fixed_at or old.created_at),
        digest=protocol_digest(old.settings), shown=shown)


def _check_datasets(profile: ExperimentProfile, domains: Mapping[str, Any]) -> None:
    from sim2radar.experiment.data import check_disjoint_worlds, check_not_the_same

    real = domains["real"]
    for role, ds in domains.items():
        if role != "real":
            check_not_the_same(ds, real)
            check_disjoint_worlds(ds, real)
    for split in (profile.train_split, profile.eval_split):
        if not real.splits.get(split):
            raise ValueError(f"{real.root}/ImageSets/{split}.txt lists no frame: the real "
                             f"dataset needs a {split!r} split")


def _intensity_matches(profile: ExperimentProfile, domains: Mapping[str, Any], pretrains,
                       nfeat: int, classes: Sequence[str]) -> dict[str, dict[str, Any]]:
    """Load (so check: shape, dtype, finite values, labels; the file named) every frame the
    sweep will read, refuse a simulated dataset holding a real validation or test frame, and
    fit each pre-training's intensity match: its sim frames onto the intensities of its runs'
    own real fine-tuning subset (:attr:`~.plan.PretrainSpec.real_ids`)."""
    from sim2radar.experiment.data import check_no_shared_frames, fit_subset_intensity_match

    real = domains["real"]
    held_out_splits = [s for s in dict.fromkeys((profile.val_split, profile.eval_split))
                       if real.splits.get(s)]
    real_train = real.frames(real.splits[profile.train_split], nfeat, classes)
    if not any(len(f.names) for f in real_train):
        raise ValueError(f"{real.root}: its {profile.train_split!r} split holds no label of "
                         f"the detector's classes {list(classes)}: every run would train on no "
                         "box; check the class names in labels/*.txt")
    held_out = real.frames(real.ids(held_out_splits), nfeat, classes)
    sims = {role: ds.frames(ds.ids(), nfeat, classes) for role, ds in domains.items()
            if role != "real"}
    for role, frames in sims.items():
        check_no_shared_frames(domains[role], real, frames, held_out)
    del held_out
    if not (profile.intensity_matching and nfeat > 3):
        return {}
    return {p.name: fit_subset_intensity_match(sims[p.sim_role], real_train,
                                               p.real_ids).to_dict() for p in pretrains}


def build_plan(setup: SweepSetup, domains: Mapping[str, Any], *, name: str, sweep_dir: str,
               store: str, fixed_at: str, key_of: KeyFn,
               provenance: Mapping[str, Any]) -> SweepPlan:
    """Check the datasets and plan the sweep: every pre-training and run with its key.

    Parameters
    ----------
    setup : :func:`setup_sweep`.
    domains : role -> opened :class:`~sim2radar.experiment.data.DomainDataset`, for (at least)
        each of ``setup.roles``.
    name, sweep_dir, store : the sweep's name, folder and artifact store root.
    fixed_at : when its settings were fixed (:func:`settings_fixed_at`).
    key_of : :data:`KeyFn`, turning key inputs into content keys.
    provenance : ``versions`` and ``code`` for sweep.json (the configs are added).

    Raises
    ------
    ValueError, DatasetError — naming the dataset, split, file or frame at fault.
    """
    from sim2radar.experiment.stats import DEFAULT_METRIC

    profile, device, settings = setup.profile, setup.device, setup.settings
    domains = {role: domains[role] for role in setup.roles}
    _check_datasets(profile, domains)
    real = domains["real"]
    pre_cfg, ft_cfg = setup.configs
    if device is not None:
        pre_cfg = pre_cfg.with_updates(runtime={"device": device})
        ft_cfg = ft_cfg.with_updates(runtime={"device": device})
    pre_dump = pre_cfg.model_dump(mode="json")
    specs, run_specs = plan_sweep(profile, real.splits[profile.train_split], setup.conditions)
    matches = _intensity_matches(profile, domains, specs, ft_cfg.model.num_point_features,
                                 ft_cfg.model.class_names)
    users = {p.name: tuple(dict.fromkeys(r.condition for r in run_specs
                                         if r.pretrain is not None and r.pretrain.name == p.name))
             for p in specs}
    pretrains = tuple(PlannedPretrain(
        spec=p, key=key_of("pretrain", {"sim": domains[p.sim_role].key},
                           pretrain_key_inputs(p, pre_dump, matches.get(p.name))),
        intensity_match=matches.get(p.name), conditions=users[p.name]) for p in specs)
    pre_key = {p.id: p.key for p in pretrains}
    runs = []
    for r in run_specs:
        pkey = pre_key[r.pretrain.name] if r.pretrain else None
        detector = condition_config(ft_cfg, r.condition).model_dump(mode="json")
        runs.append(PlannedRun(spec=r, key=key_of("finetune", {"real": real.key}, run_key_inputs(
            r, profile, detector, pkey)), pretrain_key=pkey))
    context = SweepContext(
        name=name, sweep_dir=sweep_dir, store=store,
        datasets={role: DatasetRef(root=str(ds.root), key=ds.key,
                                   splits={k: tuple(v) for k, v in ds.splits.items()})
                  for role, ds in domains.items()},
        pretrain_config=pre_cfg, finetune_config=ft_cfg, eval_split=profile.eval_split,
        val_split=profile.val_split, val_every=profile.val_every,
        max_val_points=profile.max_val_points, device=device)
    sweep = SweepDocument(**{
        "name": name, "profile": profile.model_dump(mode="json"),
        "conditions": list(dict.fromkeys(["baseline", *setup.conditions])),
        "fractions": list(profile.fractions), "trials": profile.trials, "metric": DEFAULT_METRIC,
        "datasets": {role: ds.describe() for role, ds in domains.items()},
        "real_domain": real.domain, "real_is_proxy": real.is_proxy, "intensity_match": matches,
        "n_pretrains": len(pretrains), "n_runs": len(runs),
        "provenance": {**provenance, "configs": {"pretrain": pre_dump,
                                                 "finetune": ft_cfg.model_dump(mode="json")}},
        "settings": dict(settings), "settings_digest": protocol_digest(settings),
        "settings_fixed_at": fixed_at, "created_at": _now(),
        "precision": dict(setup.precision),
        "preregistration": None if setup.preregistration is None else {
            "file": PREREGISTRATION_FILE, "sha256": setup.preregistration["sha256"],
            "source": setup.preregistration["path"]},
    })
    return SweepPlan(context=context, pretrains=pretrains, runs=tuple(runs), sweep=sweep,
                     concurrent_runs=profile.concurrent_runs, metric=DEFAULT_METRIC)
