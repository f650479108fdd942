"""The experiment sweep's tasks: content keys, caching, store I/O and outcome records around
:mod:`sim2radar.experiment` (no science here).

Identity. A pre-training run is keyed by its sim dataset's digest and
:func:`sim2radar.experiment.plan.pretrain_key_inputs` (role, seed, epochs, detector, intensity
matching); a fine-tuning run by the real dataset's digest and
:func:`~sim2radar.experiment.plan.run_key_inputs` (condition, fraction, trial seed, frames,
epochs, detector, its pre-training's key, evaluation settings); both with the code version
(:data:`EXPERIMENT_STAGE_VERSION` and the package version). :func:`prepare_sweep` computes every
key up front. A finished fine-tuning run is one
``experiment_runs`` artifact in the store under its key: a rerun finds it and reports the run as
``skipped``; a run killed half-way resumes from its last checkpoint in the sweep folder
(``<sweep>/runs/<key>/``, ``<sweep>/pretrain/<key>/``). Failed runs are not stored (a rerun
retries them); they are recorded in the sweep's ``runs.parquet`` with their error.

Claims. Before training, a run (or pre-training) is claimed in ``<sweep>/claims/``
(:mod:`sim2radar.experiment.claims`): a second sweep process or Dask worker that reaches the
same run waits for its result instead of training it again, and a claim whose process died (a
killed Dask worker) is taken over and the run resumed from its last checkpoint.

Retries: none. Training is deterministic given its inputs, so a failure would only fail again;
the store writes are local or retried by the store itself.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
import logging
import os
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pyarrow as pa
from prefect import task
from prefect.cache_policies import NO_CACHE
from sim2radar.storage import content_key, get_schema
from sim2radar.storage.provenance import package_versions
from sim2radar.storage.store import CorruptArtifactError
from sim2radar.tasks.common import open_store

from sim2radar.fileio import atomic_write_with, jsonable

__all__ = [
    "EXPERIMENT_STAGE_VERSION",
    "SweepContext",
    "SweepSettingsChanged",
    "prepare_sweep",
    "plan_cost",
    "run_pretraining",
    "run_finetuning",
    "failed_row",
    "finish_sweep",
    "write_runs_table",
    "read_runs_table",
    "write_json",
    "pretrain_task",
    "finetune_task",
]

log = logging.getLogger(__name__)

#: Bump when a training run of the same inputs gives a different result (training, evaluation
#: or the row's content changed): every run is recomputed.
EXPERIMENT_STAGE_VERSION = 1
RUNS_FILE = "runs.parquet"
PLAN_FILE = "plan.json"
#: dataset roles of the conditions (sim2radar.experiment.profiles.CONDITIONS) and their flags
ROLES = ("sim", "real", "sim-gt", "sim-one-material")


def _code_version() -> dict[str, Any]:
    return {"stage_version": EXPERIMENT_STAGE_VERSION,
            "sim2radar": package_versions().get("sim2radar", "unknown")}


@dataclasses.dataclass(frozen=True)
class SweepContext:
    """What every task of one sweep needs, as plain JSON-able values (pickles to Dask workers).

    Attributes
    ----------
    name : str — the sweep's name.
    sweep_dir : str — the sweep folder (checkpoints, runs.parquet, sweep.json, ...).
    store : str — artifact store root (path or URI).
    datasets : dict — role -> {"root", "key"} (roles :data:`ROLES`).
    pretrain_config, finetune_config : dict — resolved :class:`DetectConfig` dumps.
    intensity_match : dict — pre-training id -> :meth:`IntensityMatch.to_dict` applied to its
        sim frames (fitted on that pre-training's real subset)
        before pre-training (empty without intensity matching).
    eval_split, val_split : str — the real splits for the test and the learning curves.
    val_every : int — epochs between validation APs (0: none).
    max_val_points : int — at most this many validation APs per run.
    device : str or None — torch device for every run (None: automatic).
    """

    name: str
    sweep_dir: str
    store: str
    datasets: dict[str, dict[str, str]]
    pretrain_config: dict[str, Any]
    finetune_config: dict[str, Any]
    intensity_match: dict[str, dict[str, Any]]
    eval_split: str = "test"
    val_split: str = "val"
    val_every: int = 0
    max_val_points: int = 12
    device: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SweepContext:
        return cls(**d)


def _ctx(ctx: SweepContext | dict) -> SweepContext:
    return ctx if isinstance(ctx, SweepContext) else SweepContext.from_dict(ctx)


# ---------------------------------------------------------------------------------------------
# Data (cached per process: every run of a sweep reads the same few hundred frames)
# ---------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=32)
def _frames(root: str, key: str, ids: tuple[str, ...], num_point_features: int,
            class_names: tuple[str, ...]) -> tuple:
    from sim2radar.experiment.data import open_domain

    ds = open_domain(root, "any")
    if ds.key != key:
        raise RuntimeError(f"{root} changed while the sweep ran (content digest {ds.key}, "
                           f"expected {key}); rerun the sweep")
    return tuple(ds.frames(ids, num_point_features, class_names))


def _load(ctx: SweepContext, role: str, ids, cfg) -> list:
    d = ctx.datasets[role]
    return list(_frames(d["root"], d["key"], tuple(ids), int(cfg.model.num_point_features),
                        tuple(cfg.model.class_names)))


def _split_ids(ctx: SweepContext, role: str, split: str) -> list[str]:
    from sim2radar.experiment.data import open_domain

    return open_domain(ctx.datasets[role]["root"], role).splits.get(split, [])


# ---------------------------------------------------------------------------------------------
# Preparing a sweep: datasets, configs, intensity matching, the plan and every key
# ---------------------------------------------------------------------------------------------
def _resolve_dataset(source: str | os.PathLike, role: str, store: str, sweep_dir: Path,
                     seed: int):
    """A dataset folder, or ``store:NAME[:geometry]`` exported from the store."""
    from sim2radar.tasks.dataset import export_store_dataset

    from sim2radar.experiment.data import open_domain

    text = os.fspath(source)
    if text.startswith("store:"):
        parts = text.split(":")
        name = parts[1]
        geometry = parts[2] if len(parts) > 2 else ("ground_truth" if role == "real"
                                                     or role == "sim-gt" else "reconstructed")
        folder = sweep_dir / "data" / f"{role}-{name}-{geometry}"
        export_store_dataset(store, name, geometry, folder, seed=seed)
        return open_domain(folder, role)
    if not Path(text).is_dir():
        raise FileNotFoundError(f"{role} dataset {text!r}: no such folder (give an OpenPCDet "
                                "dataset folder, or store:NAME for a dataset in the store)")
    return open_domain(text, role)


def check_sweep_name(name: str) -> None:
    """A sweep name is one safe path component (its folder is ``<out>/<name>``): letters,
    digits, '-', '_' and '.', not starting with '.' (so never ``.`` or ``..``)."""
    if not name or name.startswith(".") or not all(c.isalnum() or c in "-_." for c in name):
        raise ValueError(f"--name {name!r}: a sweep name is one folder name under --out — use "
                         "letters, digits, '-', '_' or '.', not starting with '.'")


def prepare_sweep(
    sim: str | os.PathLike,
    real: str | os.PathLike,
    *,
    profile: Any = "demo",
    name: str = "sweep",
    out: str | os.PathLike = "out/sweeps",
    store: str | os.PathLike = "out/store",
    sim_gt: str | os.PathLike | None = None,
    sim_one_material: str | os.PathLike | None = None,
    ablations: bool = False,
    overrides: dict[str, Any] | None = None,
    device: str | None = None,
    force: Sequence[str] = (),
) -> dict[str, Any]:
    """Validate the inputs and plan a sweep; writes ``<out>/<name>/sweep.json``. The runs
    named in ``force`` (ids or keys) are redone from scratch (:func:`force_runs`).

    Returns the plan the flow runs: ``name``, ``context`` (:class:`SweepContext` dict),
    ``pretrains`` and ``runs`` (spec dicts with their content ``key``; a run names its
    pre-training by ``pretrain_id``), ``concurrent_runs``, ``metric``, ``sweep`` (what
    sweep.json holds) and ``plan_path``: the plan as written to ``<out>/<name>/plan.json``,
    which is what the flow is given.

    Raises
    ------
    ValueError, FileNotFoundError, DatasetError — naming the dataset, profile or field at fault.
    """

    from sim2radar.experiment import (
        plan_sweep,
        pretrain_key_inputs,
        run_key_inputs,
    )
    from sim2radar.experiment.data import (
        check_disjoint_worlds,
        check_no_shared_frames,
        check_not_the_same,
        fit_subset_intensity_match,
    )
    from sim2radar.experiment.plan import protocol_digest, protocol_settings
    from sim2radar.experiment.stats import DEFAULT_METRIC

    check_sweep_name(name)
    prof = _profile(profile, overrides)
    sweep_dir = Path(out) / name
    pre_cfg = _resolve_precision(prof.detector_config("pretrain"), device)
    ft_cfg = _resolve_precision(prof.detector_config("finetune"), device)
    settings = protocol_settings(prof, pre_cfg.model_dump(mode="json"),
                                 ft_cfg.model_dump(mode="json"))
    fixed_at = _check_settings_unchanged(sweep_dir, name, settings)
    sweep_dir.mkdir(parents=True, exist_ok=True)
    st = open_store(store)

    sources = {"sim": sim, "real": real, "sim-gt": sim_gt, "sim-one-material": sim_one_material}
    conditions, needed = _conditions(prof, ablations, sources)
    domains = {role: _resolve_dataset(sources[role], role, st.root_uri, sweep_dir,
                                      prof.sweep_seed)
               for role in ROLES if role in needed}
    real_ds = domains["real"]
    for role, ds in domains.items():
        if role != "real":
            check_not_the_same(ds, real_ds)
            check_disjoint_worlds(ds, real_ds)
    for split in (prof.train_split, prof.eval_split):
        if not real_ds.splits.get(split):
            raise ValueError(f"{real_ds.root}/ImageSets/{split}.txt lists no frame: the real "
                             f"dataset needs a {split!r} split")

    if device is not None:
        pre_cfg = pre_cfg.with_updates(runtime={"device": device})
        ft_cfg = ft_cfg.with_updates(runtime={"device": device})
    nfeat, classes = ft_cfg.model.num_point_features, ft_cfg.model.class_names
    pretrain_dump, ft_dump = pre_cfg.model_dump(mode="json"), ft_cfg.model_dump(mode="json")
    # every frame the sweep will read is loaded — so checked (shape, dtype, finite values,
    # labels; the file named) — before the first run, and a simulated dataset that holds a
    # real validation or test frame is refused
    held_out_splits = [s for s in dict.fromkeys((prof.val_split, prof.eval_split))
                       if real_ds.splits.get(s)]
    real_train = real_ds.frames(real_ds.splits[prof.train_split], nfeat, classes)
    held_out = real_ds.frames(real_ds.ids(held_out_splits), nfeat, classes)
    sims = {role: ds.frames(ds.ids(), nfeat, classes) for role, ds in domains.items()
            if role != "real"}
    for role, frames in sims.items():
        check_no_shared_frames(domains[role], real_ds, frames, held_out)
    del held_out
    pretrains, runs = plan_sweep(prof, real_ds.splits[prof.train_split], conditions)
    # intensity matching: each pre-training's sim frames mapped onto the intensities of its
    # runs' own real fine-tuning subset (plan.PretrainSpec.real_ids)
    matches: dict[str, dict] = {}
    if prof.intensity_matching and nfeat > 3:
        for p in pretrains:
            matches[p.name] = fit_subset_intensity_match(sims[p.sim_role], real_train,
                                                         p.real_ids).to_dict()
    pre_out, pre_key = [], {}
    for p in pretrains:
        key = content_key(
            stage="experiment_pretrain", stage_version=EXPERIMENT_STAGE_VERSION,
            inputs={"sim": domains[p.sim_role].key},
            config={**pretrain_key_inputs(p, pretrain_dump, matches.get(p.name)),
                    "code": _code_version()})
        pre_key[p.name] = key
        pre_out.append({**p.to_dict(), "id": p.name, "key": key})
    run_out = []
    for r in runs:
        pkey = pre_key[r.pretrain.name] if r.pretrain else None
        key = content_key(
            stage="experiment_runs", stage_version=EXPERIMENT_STAGE_VERSION,
            inputs={"real": real_ds.key},
            config={**run_key_inputs(r, prof, ft_dump, pkey), "code": _code_version()})
        d = r.to_dict()
        d.pop("pretrain")
        run_out.append({**d, "id": r.name, "key": key,
                        "pretrain_id": r.pretrain.name if r.pretrain else None})

    ctx = SweepContext(
        name=name, sweep_dir=str(sweep_dir.resolve()), store=st.root_uri,
        datasets={role: {"root": str(ds.root), "key": ds.key} for role, ds in domains.items()},
        pretrain_config=pretrain_dump, finetune_config=ft_dump, intensity_match=matches,
        eval_split=prof.eval_split, val_split=prof.val_split, val_every=prof.val_every,
        max_val_points=prof.max_val_points, device=device)
    sweep = {
        "name": name, "profile": prof.model_dump(mode="json"), "conditions": list(
            dict.fromkeys(["baseline", *conditions])),
        "fractions": list(prof.fractions), "trials": prof.trials, "metric": DEFAULT_METRIC,
        "datasets": {role: ds.describe() for role, ds in domains.items()},
        "real_domain": real_ds.domain, "real_is_proxy": real_ds.is_proxy,
        "intensity_match": matches,
        "n_pretrains": len(pre_out), "n_runs": len(run_out),
        "provenance": {"versions": package_versions(), "code": _code_version(),
                       "configs": {"pretrain": pretrain_dump, "finetune": ft_dump}},
        "settings": settings, "settings_digest": protocol_digest(settings),
        "settings_fixed_at": fixed_at,
        "created_at": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    write_json(sweep_dir / "sweep.json", sweep)
    if force:
        force_runs(store, sweep_dir, run_out, force)
    plan = {"name": name, "context": ctx.to_dict(), "pretrains": pre_out, "runs": run_out,
            "concurrent_runs": prof.concurrent_runs, "metric": DEFAULT_METRIC, "sweep": sweep}
    # the flow takes this file's path, not the plan: a paper-sized grid's plan (run subsets,
    # 25 intensity matches) is ~1 MB, over the 512 KiB Prefect allows for a flow run's parameters
    plan["plan_path"] = str(write_json(sweep_dir / PLAN_FILE, plan).resolve())
    return plan


def read_plan(plan_path: str | os.PathLike) -> dict[str, Any]:
    """The plan :func:`prepare_sweep` wrote (``<sweep>/plan.json``), with its ``plan_path``."""
    path = Path(plan_path)
    try:
        return {**json.loads(path.read_text()), "plan_path": str(path)}
    except (OSError, json.JSONDecodeError) as exc:
        raise FileNotFoundError(f"{path}: not a sweep plan ({exc}); prepare the sweep again "
                                "(sim2radar sweep writes it before the flow starts)") from exc


def _profile(profile: Any, overrides: dict[str, Any] | None):
    """A profile (name, path or object) with ``overrides`` applied and validated."""
    from sim2radar.experiment import load_profile
    from sim2radar.experiment.profiles import ExperimentProfile

    prof = profile if isinstance(profile, ExperimentProfile) else load_profile(profile)
    if overrides:
        try:
            prof = ExperimentProfile.model_validate({**prof.model_dump(), **overrides})
        except Exception as exc:  # pydantic's message names the field
            raise ValueError(f"profile {prof.name!r} overrides: {exc}") from None
    return prof


def _conditions(prof, ablations: bool, sources: dict[str, Any]) -> tuple[list[str], set[str]]:
    """The sweep's conditions and the dataset roles they need; raises ValueError naming the
    missing datasets' flags."""
    from sim2radar.experiment import ABLATIONS, CONDITIONS

    conditions = list(prof.all_conditions)
    if ablations:
        conditions += [c for c in ABLATIONS if c not in conditions]
    needed = {"real"} | {CONDITIONS[c].sim_role for c in conditions if CONDITIONS[c].sim_role}
    missing = sorted(r for r in needed if sources[r] is None)
    if missing:
        flags = {"sim-gt": "--sim-gt", "sim-one-material": "--sim-one-material"}
        raise ValueError("conditions " + ", ".join(c for c in conditions
                                                     if CONDITIONS[c].sim_role in missing)
                         + " need the dataset(s) " + ", ".join(flags.get(r, r) for r in missing))
    return conditions, needed


def plan_cost(
    sim: str | os.PathLike,
    real: str | os.PathLike,
    *,
    profile: Any = "demo",
    store: str | os.PathLike = "out/store",
    sim_gt: str | os.PathLike | None = None,
    sim_one_material: str | os.PathLike | None = None,
    ablations: bool = False,
    overrides: dict[str, Any] | None = None,
    device: str | None = None,
    workers: tuple[int, ...] = (1, 8),
    step_seconds: dict[str, float] | None = None,
) -> dict[str, Any]:
    """What a sweep would cost, without creating it (nothing is written to the sweeps folder):
    its jobs, their optimiser steps, seconds per step measured here on the sweep's own frames
    with its resolved configs (or ``step_seconds`` = ``{"pretrain": s, "finetune": s}``, e.g.
    a GPU's figures), and the expected wall time on each of ``workers`` worker counts
    (:func:`sim2radar.experiment.cost.wall_time`).

    Returns ``profile``, ``precision`` (amp per stage), ``jobs`` (kind -> count, steps),
    ``step_seconds``, ``measured`` (whether timed here), ``compute_hours`` and ``wall_hours``
    (workers -> hours).
    """
    import tempfile

    from sim2radar.experiment import plan_sweep
    from sim2radar.experiment.cost import measure_step_seconds, sweep_jobs, wall_time

    prof = _profile(profile, overrides)
    sources = {"sim": sim, "real": real, "sim-gt": sim_gt, "sim-one-material": sim_one_material}
    conditions, needed = _conditions(prof, ablations, sources)
    pre_cfg = _resolve_precision(prof.detector_config("pretrain"), device)
    ft_cfg = _resolve_precision(prof.detector_config("finetune"), device)
    st = open_store(store)
    with tempfile.TemporaryDirectory(prefix="sim2radar-plan-") as tmp:
        domains = {role: _resolve_dataset(sources[role], role, st.root_uri, Path(tmp),
                                          prof.sweep_seed) for role in needed}
        real_ds = domains["real"]
        train_ids = real_ds.splits.get(prof.train_split) or []
        if not train_ids:
            raise ValueError(f"{real_ds.root}/ImageSets/{prof.train_split}.txt lists no frame")
        pretrains, runs = plan_sweep(prof, train_ids, conditions)
        n_sim = {role: len(ds.ids()) for role, ds in domains.items() if role != "real"}
        jobs = sweep_jobs(pretrains, runs, n_sim, prof.batch_size)
        measured = step_seconds is None
        if measured:
            nfeat, classes = ft_cfg.model.num_point_features, ft_cfg.model.class_names
            sec = {"finetune": measure_step_seconds(
                ft_cfg, real_ds.frames(train_ids[: 3 * prof.batch_size], nfeat, classes),
                device=device)}
            if pretrains:
                sim_ds = domains[pretrains[0].sim_role]
                sec["pretrain"] = measure_step_seconds(
                    pre_cfg, sim_ds.frames(sim_ds.ids()[: 3 * prof.batch_size], nfeat, classes),
                    device=device)
        else:
            sec = {k: float(v) for k, v in step_seconds.items()}
            missing = {j.kind for j in jobs} - set(sec)
            if missing:
                raise ValueError(f"step_seconds lacks {sorted(missing)} (give pretrain and "
                                 "finetune seconds per step)")
    by_kind = {k: {"jobs": sum(j.kind == k for j in jobs),
                   "steps": sum(j.steps for j in jobs if j.kind == k)}
               for k in ("pretrain", "finetune")}
    compute_s = sum(j.steps * sec[j.kind] for j in jobs)
    return {"profile": prof.name, "device": device or str(ft_cfg.runtime.device or "auto"),
            "precision": {"pretrain": pre_cfg.runtime.amp, "finetune": ft_cfg.runtime.amp},
            "threads_per_run": prof.threads_per_run, "jobs": by_kind, "step_seconds": sec,
            "measured": measured, "compute_hours": compute_s / 3600,
            "wall_hours": {int(n): wall_time(jobs, sec, int(n)) / 3600 for n in workers}}


def _resolve_precision(cfg, device: str | None):
    """``runtime.amp: auto`` decided once, for the sweep's device, on the machine that plans
    it: every run of the sweep trains in the same precision wherever it executes, and the
    choice is part of the runs' keys and the sweep's settings."""
    from sim2radar.hardware import autocast_dtype, torch_device

    if cfg.runtime.amp != "auto":
        return cfg
    dev = torch_device(device or cfg.runtime.device)
    return cfg.with_updates(runtime={"amp": autocast_dtype(dev, "auto") is not None})


class SweepSettingsChanged(ValueError):
    """A sweep folder's settings were fixed by its first preparation and now differ."""


def _check_settings_unchanged(sweep_dir: Path, name: str, settings: dict[str, Any]) -> str:
    """Refuse to rerun a sweep whose protocol settings changed since it was created; returns
    when they were fixed (now, for a new sweep; the first preparation's time otherwise).

    A sweep's results must come from one set of settings, fixed before its first run: a
    profile edited after some runs finished would mix two protocols in one table (and invites
    tuning the protocol toward the answer). A folder written before settings were recorded
    adopts the current ones.
    """
    from sim2radar.experiment.plan import protocol_digest, settings_changes

    now = datetime.now(UTC).isoformat(timespec="seconds")
    path = sweep_dir / "sweep.json"
    if not path.is_file():
        return now
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: unreadable ({exc}); delete it (and the sweep folder's runs "
                         "if they are not wanted) or choose a new sweep name") from None
    if "settings" not in old:
        return str(old.get("created_at") or now)
    if protocol_digest(old["settings"]) == protocol_digest(settings):
        return str(old.get("settings_fixed_at") or old.get("created_at") or now)
    changes = settings_changes(old["settings"], settings)
    shown = "\n  ".join(changes[:12]) + (f"\n  ... and {len(changes) - 12} more"
                                          if len(changes) > 12 else "")
    raise SweepSettingsChanged(
        f"sweep {name!r} ({sweep_dir}) was created with other settings (fixed at "
        f"{old.get('settings_fixed_at') or old.get('created_at')}, digest "
        f"{protocol_digest(old['settings'])}); what changed:\n  {shown}\n"
        "One sweep's runs all use the settings fixed before its first run: start a new sweep "
        "name (--name) for the new settings, or delete the folder to discard the old sweep.")


# ---------------------------------------------------------------------------------------------
# Runs (plain functions; the Prefect tasks below only wrap them)
# ---------------------------------------------------------------------------------------------
def run_pretraining(ctx: SweepContext | dict, spec: dict[str, Any]) -> dict[str, Any]:
    """Pre-train (or find finished) the encoder of ``spec`` (a planned pre-training with its
    ``key``); returns ``{"key", "checkpoint", "n_frames"}``."""
    from sim2radar.detect.config import DetectConfig
    from sim2radar.experiment.data import open_domain, with_intensity
    from sim2radar.experiment.runner import pretrain_encoder
    from sim2radar.radar.intensity import IntensityMatch

    ctx = _ctx(ctx)
    role = spec["sim_role"]
    cfg = DetectConfig.model_validate(ctx.pretrain_config)
    sim = open_domain(ctx.datasets[role]["root"], role)
    frames = _load(ctx, role, sim.ids(), cfg)
    if spec["id"] in ctx.intensity_match:
        frames = with_intensity(frames, IntensityMatch.from_dict(ctx.intensity_match[spec["id"]]))
    out = Path(ctx.sweep_dir) / "pretrain" / spec["key"]
    claim = _claim(ctx, spec["key"], lambda: (out / "done.json").is_file(), out,
                   f"pre-training {spec['id']}")
    with claim or contextlib.nullcontext():     # None: finished, pretrain_encoder reads it
        ckpt = pretrain_encoder(cfg, frames, out, seed=int(spec["seed"]),
                                epochs=int(spec["epochs"]), device=ctx.device)
    return {"key": spec["key"], "checkpoint": str(ckpt), "n_frames": len(frames)}


def _claim(ctx: SweepContext, key: str, done, out: Path, what: str):
    """Claim a run for this process (:mod:`sim2radar.experiment.claims`), waiting while another
    live process trains it; None once it is finished (by anyone)."""
    from sim2radar.experiment.claims import wait_and_claim

    def waiting(holder: dict) -> None:
        log.info("%s is being trained by pid %s on %s; waiting for it", what,
                 holder.get("pid"), holder.get("host"))

    return wait_and_claim(Path(ctx.sweep_dir) / "claims", key, done,
                          note=lambda: {"resume": (out / "last.pt").is_file()},
                          on_wait=waiting)


def _base_row(ctx: SweepContext, spec: dict[str, Any],
              pretrain: dict[str, Any] | None) -> dict[str, Any]:
    n_sim = int(pretrain["n_frames"]) if pretrain else 0
    return {
        "sweep": ctx.name, "run_key": spec["key"], "condition": spec["condition"],
        "fraction": float(spec["fraction"]), "n_real_frames": int(spec["n_real"]),
        "n_sim_frames": n_sim,
        "sim_real_ratio": (n_sim / int(spec["n_real"])) if pretrain else None,
        "trial": int(spec["trial"]), "seed": int(spec["seed"]),
        "pretrain_key": pretrain["key"] if pretrain else None,
    }


def run_finetuning(ctx: SweepContext | dict, spec: dict[str, Any],
                   pretrain: dict[str, Any] | None) -> dict[str, Any]:
    """Fine-tune and test one cell's run (or read it back); returns its experiment_runs row
    with ``status`` ``ok`` (computed now) or ``skipped`` (found in the store)."""

    ctx = _ctx(ctx)
    st = open_store(ctx.store)
    key = spec["key"]
    out = Path(ctx.sweep_dir) / "runs" / key
    for _ in range(2):
        claim = _claim(ctx, key, lambda: st.exists("experiment_runs", key), out,
                       f"run {spec['id']}")
        if claim is not None:
            break
        try:
            row = st.read("experiment_runs", key).to_pylist()[0]
        except CorruptArtifactError:  # moved into quarantine by the read: compute it again
            continue
        return {**row, "sweep": ctx.name, "status": "skipped"}
    with claim:
        return _finetune(ctx, st, spec, pretrain, out)


def force_runs(store: str, sweep_dir: Path, runs: list[dict[str, Any]],
               wanted: Sequence[str]) -> list[str]:
    """Make the sweep redo the runs named in ``wanted`` (run ids such as
    ``sim-pretrain-f0.05-t2``, or run keys): each one's stored row is moved into the store's
    quarantine and its run folder (checkpoints) into ``<sweep>/quarantine/runs/``, so it trains
    from scratch; nothing is deleted. Returns the ids forced.

    Raises
    ------
    ValueError — for a name that is no run of this sweep, with an example of the ids.
    """
    by_name = {r["id"]: r for r in runs} | {r["key"]: r for r in runs}
    unknown = [w for w in wanted if w not in by_name]
    if unknown:
        raise ValueError(f"--force-run {unknown[0]!r}: no run of this sweep has that id or key; "
                         f"run ids look like {runs[0]['id']!r} (results.md, the dashboard, "
                         "runs.parquet's run_key)")
    st = open_store(store)
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    forced = []
    for name in dict.fromkeys(wanted):
        run = by_name[name]
        path = st.path("experiment_runs", run["key"])
        if st.fs.exists(path):
            st.quarantine(path, f"--force-run {name}: redone on request")
        folder = Path(sweep_dir) / "runs" / run["key"]
        if folder.exists():
            dest = Path(sweep_dir) / "quarantine" / "runs" / f"{run['key']}.{stamp}"
            dest.parent.mkdir(parents=True, exist_ok=True)
            os.replace(folder, dest)
            log.warning("sweep: %s forced; its run folder moved to %s", run["id"], dest)
        forced.append(run["id"])
    return forced


def _finetune(ctx: SweepContext, st, spec: dict[str, Any], pretrain: dict[str, Any] | None,
              out: Path) -> dict[str, Any]:
    from sim2radar.detect.config import DetectConfig
    from sim2radar.experiment.runner import finetune_and_test

    key = spec["key"]
    cfg = DetectConfig.model_validate(ctx.finetune_config)
    train = _load(ctx, "real", spec["train_ids"], cfg)
    test = _load(ctx, "real", _split_ids(ctx, "real", ctx.eval_split), cfg)
    val = (_load(ctx, "real", _split_ids(ctx, "real", ctx.val_split), cfg)
           if ctx.val_every else [])
    fields = finetune_and_test(
        cfg, train, test, out, seed=int(spec["seed"]), epochs=int(spec["epochs"]),
        encoder_checkpoint=pretrain["checkpoint"] if pretrain else None, val_frames=val,
        val_every=ctx.val_every, max_val_points=ctx.max_val_points, device=ctx.device)
    row = {**_base_row(ctx, spec, pretrain), **fields,
           "checkpoint": os.path.relpath(out / "last.pt", Path(ctx.sweep_dir).parent),
           "status": "ok", "error": "",
           "finished_at": datetime.now(UTC).isoformat(timespec="seconds")}
    schema = get_schema("experiment_runs")
    table = schema.validate(pa.Table.from_pylist([row], schema=schema.schema))
    st.write("experiment_runs", key, table, stage_version=EXPERIMENT_STAGE_VERSION,
             provenance={"inputs": {"real": ctx.datasets["real"]["key"],
                                    "pretrain": row["pretrain_key"]},
                         "config": {"detector": ctx.finetune_config,
                                    "spec": {k: v for k, v in spec.items() if k != "train_ids"}},
                         "seed": int(spec["seed"]),
                         "timings_s": {"run": float(row["wall_time_s"])},
                         "extra": {"sweep": ctx.name, "train_ids": list(spec["train_ids"])}})
    return row


def failed_row(ctx: SweepContext | dict, spec: dict[str, Any], pretrain: dict[str, Any] | None,
               error: BaseException | str) -> dict[str, Any]:
    """The experiment_runs row of a run that failed (AP null, ``error`` set)."""
    ctx = _ctx(ctx)
    text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
    row = {c: None for c in get_schema("experiment_runs").schema.names}
    row.update(_base_row(ctx, spec, pretrain))
    row.update(epochs=int(spec["epochs"]), steps=0, history_epoch=[], history_loss=[],
               history_val_epoch=[], history_val_ap=[], wall_time_s=0.0, device="",
               checkpoint="", status="failed", error=text[:2000],
               finished_at=datetime.now(UTC).isoformat(timespec="seconds"))
    return row


def finish_sweep(plan: dict[str, Any], rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Statistics, report and dashboard of a sweep's rows; writes ``stats.json``,
    ``results.md`` and ``dashboard.html`` into the sweep folder.

    Returns ``counts`` (runs by status), ``metric``, ``stats``, ``markdown``, ``table_rows``
    (for a Prefect table artifact) and the paths ``sweep_dir``, ``results_md``, ``dashboard``.
    """
    from sim2radar.experiment import results_markdown, results_table_rows, sweep_stats
    from sim2radar.experiment.dashboard import write_dashboard

    sweep_dir = Path(plan["context"]["sweep_dir"])
    sweep = plan["sweep"]
    stats = sweep_stats(rows, plan["metric"], conditions=sweep["conditions"])
    md = results_markdown(stats, rows, title=f"Sweep {plan['name']}",
                          real_domain_label=sweep["real_domain"],
                          proxy=sweep["real_is_proxy"],
                          settings={"profile": sweep["profile"].get("name"),
                                    "digest": sweep.get("settings_digest"),
                                    "fixed_at": sweep.get("settings_fixed_at")})
    write_json(sweep_dir / "stats.json", stats)
    (sweep_dir / "results.md").write_text(md)
    dashboard = write_dashboard(sweep_dir, sweep_dir / "dashboard.html")
    counts = {k: sum(r["status"] == k for r in rows) for k in ("ok", "skipped", "failed")}
    return {"name": plan["name"], "sweep_dir": str(sweep_dir), "counts": counts,
            "metric": plan["metric"], "stats": stats, "markdown": md,
            "table_rows": results_table_rows(stats),
            "results_md": str(sweep_dir / "results.md"), "dashboard": str(dashboard)}


# ---------------------------------------------------------------------------------------------
# The sweep folder's tables
# ---------------------------------------------------------------------------------------------
def write_runs_table(sweep_dir: str | os.PathLike, rows: list[dict[str, Any]]) -> Path:
    """Write ``<sweep>/runs.parquet`` atomically (validated against experiment_runs)."""
    import pyarrow.parquet as pq

    schema = get_schema("experiment_runs")
    table = schema.validate(pa.Table.from_pylist(rows, schema=schema.schema))
    path = Path(sweep_dir) / RUNS_FILE
    atomic_write_with(path, lambda tmp: pq.write_table(table, tmp))
    return path


def read_runs_table(sweep_dir: str | os.PathLike) -> list[dict[str, Any]]:
    """The rows of ``<sweep>/runs.parquet`` (empty when the sweep has none yet)."""
    import pyarrow.parquet as pq

    path = Path(sweep_dir) / RUNS_FILE
    return pq.read_table(path).to_pylist() if path.is_file() else []


def write_json(path: str | os.PathLike, doc: Any) -> Path:
    """Write JSON atomically (for sweep.json, stats.json, progress.json), numpy values as
    numbers (:func:`sim2radar.fileio.jsonable`)."""
    from sim2radar.fileio import write_json as write

    return write(path, jsonable(doc))


# ---------------------------------------------------------------------------------------------
# Prefect tasks: no retries (deterministic training); caching by content key inside.
# ---------------------------------------------------------------------------------------------
@task(name="pretrain-encoder", cache_policy=NO_CACHE, retries=0, persist_result=False)
def pretrain_task(ctx: dict, spec: dict) -> dict:
    """Prefect task around :func:`run_pretraining`."""
    return run_pretraining(ctx, spec)


@task(name="finetune-and-test", cache_policy=NO_CACHE, retries=0, persist_result=False)
def finetune_task(ctx: dict, spec: dict, pretrain: dict | None) -> dict:
    """Prefect task around :func:`run_finetuning`."""
    return run_finetuning(ctx, spec, pretrain)
