"""The experiment sweep's work: content keys, caching, store I/O and outcome records around
:mod:`sim2radar.experiment`; it executes a :class:`~sim2radar.experiment.plan.SweepPlan`
(planned by :mod:`sim2radar.experiment.prepare`, summed up at the end by
:mod:`sim2radar.experiment.finish`). Plain functions, no
Prefect import: ``flows/run_experiment.py`` wraps :func:`run_pretraining` and
:func:`run_finetuning` in its Prefect tasks.

Identity. A pre-training run is keyed by its sim dataset's digest and
:func:`sim2radar.experiment.plan.pretrain_key_inputs` (role, seed, epochs, detector, intensity
matching); a fine-tuning run by the real dataset's digest and
:func:`~sim2radar.experiment.plan.run_key_inputs` (condition, fraction, trial seed, frames,
epochs, detector, its pre-training's key, evaluation settings); both with the code version
(:data:`EXPERIMENT_STAGE_VERSION` and the package version). :func:`prepare_sweep` computes every
key up front (:func:`_key_of`). A finished fine-tuning run is one ``experiment_runs`` artifact in
the store under its key: a rerun finds it and reports the run as ``skipped``; a run killed
half-way resumes from its last checkpoint in the sweep folder (``<sweep>/runs/<key>/``,
``<sweep>/pretrain/<key>/``). Failed runs are not stored (a rerun retries them); they are
recorded in the sweep's ``runs.parquet`` with their error.

Claims. Before training, a run (or pre-training) is claimed in ``<sweep>/claims/``
(:mod:`sim2radar.experiment.claims`): a second sweep process or Dask worker that reaches the
same run waits for its result instead of training it again, and a claim whose process died (a
killed Dask worker) is taken over and the run resumed from its last checkpoint.

Retries: none. Training is deterministic given its inputs, so a failure would only fail again;
the store writes are local or retried by the store itself.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import math
import os
import tempfile
import time
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pyarrow as pa

from sim2radar.experiment import prepare
from sim2radar.experiment.errors import SettingError
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.plan import (
    PlannedPretrain,
    PlannedRun,
    PretrainResult,
    SweepContext,
    SweepPlan,
    condition_config,
)
from sim2radar.fileio import atomic_write, atomic_write_with, write_json
from sim2radar.storage import content_key, get_schema
from sim2radar.storage.provenance import git_commit, package_versions
from sim2radar.storage.store import CorruptArtifactError
from sim2radar.tasks.common import open_store

__all__ = ["EXPERIMENT_STAGE_VERSION", "prepare_sweep", "read_plan", "plan_cost",
           "run_pretraining", "run_finetuning", "force_runs", "failed_row", "write_runs_table",
           "failed_pretrain_row", "write_pretrainings_table"]

log = logging.getLogger(__name__)

#: Bump when a training run of the same inputs gives a different result (training, evaluation
#: or the row's content changed): every run is recomputed. (2: the pillar net's linear layer
#: runs in float32 under bfloat16 autocast)
EXPERIMENT_STAGE_VERSION = 2
#: store stage of each kind of training job
STAGES = {"pretrain": "experiment_pretrain", "finetune": "experiment_runs"}
#: folder under the sweeps root holding the measured precision decisions
#: (:func:`sim2radar.detect.precision.decide_precision`), one per device and model
PRECISION_TABLE = ".precision"


def _code_version() -> dict[str, Any]:
    return {"stage_version": EXPERIMENT_STAGE_VERSION,
            "sim2radar": package_versions().get("sim2radar", "unknown")}


def _key_of(kind: str, inputs: Mapping[str, str], key_inputs: Mapping[str, Any]) -> str:
    """A job's content key (:data:`sim2radar.experiment.prepare.KeyFn`)."""
    return content_key(stage=STAGES[kind], stage_version=EXPERIMENT_STAGE_VERSION,
                       inputs=dict(inputs), config={**key_inputs, "code": _code_version()})


# --- Data (cached per process: every run of a sweep reads the same few hundred frames)
@functools.lru_cache(maxsize=32)
def _frames(root: str, key: str, ids: tuple[str, ...], num_point_features: int,
            class_names: tuple[str, ...]) -> tuple:
    from sim2radar.experiment.data import open_domain

    ds = open_domain(root, "any")
    if ds.key != key:
        raise RuntimeError(f"{root} changed while the sweep ran (content digest {ds.key}, "
                           f"expected {key}); rerun the sweep")
    return tuple(ds.frames(ids, num_point_features, class_names))


def _load(ctx: SweepContext, role: str, ids: Sequence[str], cfg) -> list:
    d = ctx.datasets[role]
    return list(_frames(d.root, d.key, tuple(ids), int(cfg.model.num_point_features),
                        tuple(cfg.model.class_names)))


# --- Preparing a sweep: its datasets from the store or folders, the plan and the sweep folder
def _export(store: str, folder: Path, seed: int, role: str, name: str, geometry: str) -> Path:
    """Export a store dataset for a sweep
    (:func:`sim2radar.experiment.prepare.open_datasets`)."""
    from sim2radar.tasks.dataset import export_store_dataset

    dest = folder / "data" / f"{role}-{name}-{geometry}"
    export_store_dataset(store, name, geometry, dest, seed=seed)
    return dest


def prepare_sweep(datasets: Mapping[str, str | os.PathLike | None], *, profile: Any = "demo",
                  name: str = "sweep", out: str | os.PathLike = "out/sweeps",
                  store: str | os.PathLike = "out/store", ablations: bool = False,
                  overrides: dict[str, Any] | None = None, device: str | None = None,
                  force: Sequence[str] = ()) -> SweepPlan:
    """Validate the inputs and plan a sweep; writes ``<out>/<name>/sweep.json`` and
    ``plan.json`` (the plan the flow is given by path: :attr:`SweepPlan.plan_path`). The runs
    named in ``force`` (ids or keys) are redone from scratch (:func:`force_runs`).

    ``datasets``: role (:data:`sim2radar.experiment.profiles.ROLES`) -> dataset folder or
    ``store:NAME[:geometry]``; ``sim`` and ``real``, and the ablations' roles with ``ablations``.

    Raises
    ------
    ValueError, FileNotFoundError, DatasetError — naming the dataset, profile or field at fault.
    """
    prepare.check_sweep_name(name)
    folder = SweepFolder(Path(out) / name)
    sweep_dir = folder.root
    old = folder.read_sweep_document()       # a damaged sweep.json is refused, in one line
    # a sweep keeps the precision it decided first (its runs' keys depend on it)
    known = old.held("precision") if old is not None else None
    setup = prepare.setup_sweep(profile, datasets, ablations=ablations, overrides=overrides,
                                device=device, precision_table=Path(out) / PRECISION_TABLE,
                                known_precision=known if isinstance(known, dict) else None)
    fixed_at = prepare.settings_fixed_at(old, setup.settings, name=name, sweep_dir=sweep_dir)
    sweep_dir.mkdir(parents=True, exist_ok=True)
    st = open_store(store)
    domains = prepare.open_datasets(datasets, setup.roles, functools.partial(
        _export, st.root_uri, sweep_dir, setup.profile.sweep_seed))
    plan = prepare.build_plan(
        setup, domains, name=name, sweep_dir=str(sweep_dir.resolve()), store=st.root_uri,
        fixed_at=fixed_at, key_of=_key_of,
        provenance={"versions": package_versions(), "code": _code_version(),
                    "git": git_commit()})
    folder.write_sweep_document(plan.sweep)
    if setup.preregistration is not None:   # the copy the results link (same digest: settings)
        atomic_write(folder.preregistration_md, setup.preregistration["text"].encode())
    if force:
        force_runs(st.root_uri, sweep_dir, plan.find_runs(force))
    # the flow takes this file's path, not the plan: a paper-sized grid's plan (run subsets,
    # 25 intensity matches) is ~1 MB, over the 512 KiB Prefect allows for a flow run's parameters
    path = write_json(folder.plan_json, plan.model_dump(mode="json")).resolve()
    return plan.model_copy(update={"plan_path": str(path)})


def parse_runs_per_gpu(value: int | str | None) -> int | str | None:
    """``--runs-per-gpu``: a count >= 1, ``"auto"``, or None (not packing).

    Raises
    ------
    SettingError — anything else, naming the setting (``runs_per_gpu``).
    """
    if value is None or value == "auto":
        return value
    text = str(value).strip()
    if isinstance(value, bool) or not text.isdigit() or int(text) < 1:
        raise SettingError("{runs_per_gpu} must be a count >= 1 or 'auto', got {value}",
                           value=repr(value))
    return int(text)


def cuda_devices(device: str | None) -> int:
    """How many GPUs a sweep on ``device`` packs runs onto: 1 for ``cuda:K``, every visible
    GPU for ``cuda`` or an automatic device on a GPU machine.

    Raises
    ------
    SettingError — the device is not a CUDA GPU (runs per GPU mean nothing there).
    """
    import torch

    from sim2radar.hardware import torch_device

    dev = torch_device(device)
    if dev.type != "cuda":
        raise SettingError("{runs_per_gpu}: the sweep's device is {device}, not a CUDA GPU; "
                           "on a CPU give {workers} (concurrent runs) instead", device=str(dev))
    return 1 if dev.index is not None else max(1, torch.cuda.device_count())


def pack_runs(plan: SweepPlan, runs_per_gpu: int | str, *, steps: int = 20):
    """How many of ``plan``'s training runs share each GPU
    (:class:`~sim2radar.experiment.packing.PackingDecision`): ``runs_per_gpu`` as given, or
    for ``"auto"`` measured (:func:`~sim2radar.experiment.packing.aggregate_throughput` of the
    sweep's fine-tuning model, 1/2/4/8 processes and doubling while it pays,
    :func:`~.packing.probe_runs`, :func:`~.packing.choose_runs`). The decision
    is recorded in the sweep's ``sweep.json`` (``packing``, with the number of GPUs).

    Raises
    ------
    ValueError — the sweep's device is not a CUDA GPU, or a bad count.
    """
    from sim2radar.experiment.packing import decide_runs
    from sim2radar.hardware import torch_device

    runs_per_gpu = parse_runs_per_gpu(runs_per_gpu)
    n_gpus = cuda_devices(plan.context.device)
    cfg = plan.context.finetune_config
    device = str(torch_device(plan.context.device or cfg.runtime.device))
    decision = decide_runs(cfg, device, runs_per_gpu, steps=steps)
    SweepFolder(plan.context.sweep_dir).update_sweep(
        packing={**decision.to_dict(), "gpus": n_gpus})
    return decision, n_gpus


def read_plan(plan_path: str | os.PathLike) -> SweepPlan:
    """The plan :func:`prepare_sweep` wrote (``<sweep>/plan.json``), with its ``plan_path``."""
    path = Path(plan_path)
    try:
        plan = SweepPlan.model_validate(json.loads(path.read_text()))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise FileNotFoundError(f"{path}: not a sweep plan ({exc}); prepare the sweep again "
                                "(sim2radar sweep writes it before the flow starts)") from exc
    return plan.model_copy(update={"plan_path": str(path)})


def plan_cost(datasets: Mapping[str, str | os.PathLike | None], *, profile: Any = "demo",
              store: str | os.PathLike = "out/store", out: str | os.PathLike = "out/sweeps",
              ablations: bool = False,
              overrides: dict[str, Any] | None = None, device: str | None = None,
              workers: tuple[int, ...] = (1, 8),
              step_seconds: dict[str, float] | None = None,
              runs_per_gpu: int | str | None = None) -> dict[str, Any]:
    """What a sweep would cost, without creating it (nothing is written to the sweeps folder;
    ``store:`` datasets are exported to a temporary folder):
    :func:`sim2radar.experiment.cost.sweep_cost` of the sweep :func:`prepare_sweep` would
    plan; mixed precision as recorded for this device under ``out``, else assumed (no probe
    runs for an estimate).

    ``runs_per_gpu`` (a count or ``"auto"``, CUDA only): the runs sharing each GPU's measured
    aggregate throughput (:func:`~sim2radar.experiment.packing.aggregate_throughput` of the
    fine-tuning model, used for both stages) sets one run's seconds per step, and the wall time
    is planned for N x GPUs concurrent runs, faster per run while fewer share a GPU as the
    measured counts say (``packing`` in the result)."""
    from sim2radar.experiment.cost import sweep_cost

    setup = prepare.setup_sweep(profile, datasets, ablations=ablations, overrides=overrides,
                                device=device, precision_table=Path(out) / PRECISION_TABLE,
                                probe=False)
    packing, sharing = None, {}
    if runs_per_gpu is not None:
        from sim2radar.experiment.packing import decide_runs
        from sim2radar.hardware import torch_device

        runs_per_gpu = parse_runs_per_gpu(runs_per_gpu)
        n_gpus = cuda_devices(device)
        ft = setup.configs[1]
        dev = str(torch_device(device or ft.runtime.device))
        decision = decide_runs(ft, dev, runs_per_gpu, measure=True)
        s = decision.seconds_per_step()
        step_seconds = {"pretrain": s, "finetune": s}
        workers = (decision.runs * n_gpus,)
        packing = {**decision.to_dict(), "gpus": n_gpus}
        sharing = {"throughput": decision.steps_per_s, "devices": n_gpus}
    with tempfile.TemporaryDirectory(prefix="sim2radar-plan-") as tmp:
        domains = prepare.open_datasets(datasets, setup.roles, functools.partial(
            _export, open_store(store).root_uri, Path(tmp), setup.profile.sweep_seed))
        cost = sweep_cost(setup, domains, workers=workers, step_seconds=step_seconds, **sharing)
    return cost if packing is None else {**cost, "packing": packing}


def force_runs(store: str, sweep_dir: str | os.PathLike,
               runs: Sequence[PlannedRun | PlannedPretrain]) -> list[str]:
    """Make the sweep redo ``runs`` (:meth:`SweepPlan.find_runs`: fine-tuning runs or
    pre-trainings): each one's stored row is moved into the store's quarantine and its folder
    (checkpoints, a pre-training's check) into ``<sweep>/quarantine/runs/`` or
    ``quarantine/pretrain/``, so it trains from scratch; nothing is deleted. A forced
    pre-training's fine-tuning runs keep their results (their key names the pre-training's
    inputs, not its bytes); force them too to retrain them. Returns the ids forced."""
    st = open_store(store)
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    for job in runs:
        kind = "pretrain" if isinstance(job, PlannedPretrain) else "runs"
        stage = STAGES["pretrain"] if kind == "pretrain" else STAGES["finetune"]
        path = st.path(stage, job.key)
        if st.fs.exists(path):
            st.quarantine(path, f"--force-run {job.id}: redone on request")
        folder = SweepFolder(sweep_dir).job_dir(kind, job.key)
        if folder.exists():
            dest = SweepFolder(sweep_dir).quarantine_dir(kind, job.key, stamp)
            dest.parent.mkdir(parents=True, exist_ok=True)
            os.replace(folder, dest)
            log.warning("sweep: %s forced; its folder moved to %s", job.id, dest)
    return [r.id for r in runs]


# --- Runs (plain functions; flows/run_experiment.py wraps them in Prefect tasks)
def _claim(ctx: SweepContext, key: str, done, out: Path, what: str):
    """Claim a run for this process (:mod:`sim2radar.experiment.claims`), waiting while another
    live process trains it; None once it is finished (by anyone)."""
    from sim2radar.experiment.claims import STALE_AFTER_S, wait_and_claim

    return wait_and_claim(
        Path(ctx.sweep_dir) / "claims", key, done,
        note=lambda: {"resume": (out / SweepFolder.LAST_CHECKPOINT).is_file()},
        on_wait=lambda holder: log.warning(
            "%s is claimed by pid %s on %s (%s); waiting for it to finish, or for its claim to "
            "go stale (no heartbeat for %.0f s: a process on another host cannot be asked "
            "whether it is alive)", what, holder.get("pid"), holder.get("host"),
            Path(ctx.sweep_dir) / "claims" / f"{key}.json", STALE_AFTER_S))


def _pretrain_ids(ctx: SweepContext, job: PlannedPretrain) -> tuple[list[str], list[str]]:
    """A pre-training's training frame ids and held-out frame ids (its sim dataset's
    ``holdout_split``; none when it has no such split)."""
    sim, spec = ctx.datasets[job.spec.sim_role], job.spec
    held = sim.ids([spec.holdout_split]) if spec.holdout_split else []
    out = set(held)
    train_ids = [i for i in sim.ids() if i not in out]
    if not train_ids:
        raise ValueError(f"{sim.root}: every frame is in the held-out split "
                         f"{spec.holdout_split!r}; nothing is left to pre-train on (export more "
                         "worlds, or set the profile's pretrain_holdout_split: null)")
    return train_ids, held


def run_pretraining(ctx: SweepContext, job: PlannedPretrain) -> PretrainResult:
    """Pre-train (or find finished) the encoder of ``job`` and check what it learned
    (:func:`sim2radar.experiment.learnability.check_pretraining`: its training frames, the
    held-out sim split, zero-shot on the real validation split). ``done.json`` and ``check.json``
    in its folder mark it finished; its ``experiment_pretrain`` row goes into the store."""
    from sim2radar.detect.train import checkpoint_loads, quarantine_file
    from sim2radar.experiment.data import with_intensity
    from sim2radar.experiment.learnability import PretrainingCheck, check_pretraining
    from sim2radar.experiment.runner import pretrain_encoder
    from sim2radar.radar.intensity import IntensityMatch

    spec, cfg = job.spec, ctx.pretrain_config
    train_ids, held_ids = _pretrain_ids(ctx, job)
    match = (IntensityMatch.from_dict(job.intensity_match) if job.intensity_match is not None
             else None)

    def sim_frames(ids: list[str]) -> list:
        frames = _load(ctx, spec.sim_role, ids, cfg)
        return with_intensity(frames, match) if match is not None and frames else frames

    out = SweepFolder(ctx.sweep_dir).pretrain_dir(job.key)
    done, checked = out / SweepFolder.DONE, out / SweepFolder.CHECK
    last = out / SweepFolder.LAST_CHECKPOINT
    if checked.is_file() and not checkpoint_loads(last):
        # finished, but its checkpoint was damaged since (now in quarantine/): redo the rest
        quarantine_file(checked, "its pre-training's last.pt does not load")
    claim = _claim(ctx, job.key, checked.is_file, out, f"pre-training {job.id}")
    status = "skipped" if claim is None else "ok"
    with claim or contextlib.nullcontext():     # None: finished, read back below
        frames = sim_frames(train_ids) if claim is not None else []
        ckpt = pretrain_encoder(cfg, frames, out, seed=spec.seed, epochs=spec.epochs,
                                device=ctx.device) if claim is not None else last
        if claim is not None:
            t0 = time.perf_counter()
            real = ctx.datasets["real"]
            check = check_pretraining(
                ckpt, sim_frames(held_ids), _load(ctx, "real", real.ids([ctx.val_split]), cfg),
                train_frames=frames, device=ctx.device)
            write_json(checked, {**check.to_dict(), "seconds": time.perf_counter() - t0})
    check_doc = json.loads(checked.read_text())
    row = _pretrain_row(ctx, job, PretrainingCheck.from_dict(check_doc),
                        json.loads(done.read_text()), float(check_doc.get("seconds", 0.0)),
                        status, out)
    st = open_store(ctx.store)
    if not st.exists(STAGES["pretrain"], job.key):
        schema = get_schema(STAGES["pretrain"])
        table = schema.validate(pa.Table.from_pylist([{**row, "status": "ok"}],
                                                     schema=schema.schema))
        st.write(STAGES["pretrain"], job.key, table, stage_version=EXPERIMENT_STAGE_VERSION,
                 provenance={"inputs": {"sim": ctx.datasets[spec.sim_role].key},
                             "config": {"detector": ctx.pretrain_config.model_dump(mode="json"),
                                        "spec": job.model_dump(mode="json")},
                             "seed": spec.seed, "timings_s": {"run": float(row["wall_time_s"])},
                             "extra": {"sweep": ctx.name, "train_ids": train_ids}})
    return PretrainResult(key=job.key, checkpoint=str(ckpt), n_frames=int(row["n_sim_frames"]),
                          row=row)


def _pretrain_row(ctx: SweepContext, job: PlannedPretrain, check, done: Mapping[str, Any],
                  check_s: float, status: str, out: Path) -> dict[str, Any]:
    """The ``experiment_pretrain`` row of a finished, checked pre-training."""
    from sim2radar.experiment.learnability import PRIMARY_AP

    hist = list(done.get("history") or [])
    bev = PRIMARY_AP.replace("_3d_", "_bev_")
    row = _pretrain_base_row(ctx, job)
    row.update(
        n_sim_frames=int(done.get("frames", 0)), n_heldout_frames=check.sim_frames,
        n_real_val_frames=check.real_frames, epochs=int(done.get("epochs", job.spec.epochs)),
        steps=int(done.get("steps", 0)), history_epoch=[int(h["epoch"]) for h in hist],
        history_loss=[float(h["total"]) for h in hist],
        wall_time_s=float(done.get("seconds", 0.0)), check_s=float(check_s),
        checkpoint=os.path.relpath(out / SweepFolder.LAST_CHECKPOINT,
                                   Path(ctx.sweep_dir).parent),
        status=status, error="", finished_at=datetime.now(UTC).isoformat(timespec="seconds"))
    for where, aps in (("train", check.train), ("heldout", check.sim),
                       ("zero_shot", check.real)):
        for col in (PRIMARY_AP, bev):
            v = aps.get(col)
            row[f"{where}_{col}"] = (
                None if v is None or not math.isfinite(float(v)) else float(v))
    return row


def _pretrain_base_row(ctx: SweepContext, job: PlannedPretrain) -> dict[str, Any]:
    spec = job.spec
    row = {c: None for c in get_schema(STAGES["pretrain"]).schema.names}
    row.update(sweep=ctx.name, pretrain_key=job.key, pretrain_id=job.id,
               sim_role=spec.sim_role, conditions=list(job.conditions), trial=spec.trial,
               fraction=spec.fraction, seed=spec.seed, holdout_split=spec.holdout_split)
    return row


def failed_pretrain_row(ctx: SweepContext, job: PlannedPretrain,
                        error: BaseException | str) -> dict[str, Any]:
    """The ``experiment_pretrain`` row of a pre-training that failed (APs null, ``error``)."""
    text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
    row = _pretrain_base_row(ctx, job)
    row.update(n_sim_frames=0, n_heldout_frames=0, n_real_val_frames=0,
               epochs=job.spec.epochs, steps=0, history_epoch=[], history_loss=[],
               wall_time_s=0.0, check_s=0.0, checkpoint="", status="failed",
               error=text[:2000], finished_at=datetime.now(UTC).isoformat(timespec="seconds"))
    return row


def write_pretrainings_table(sweep_dir: str | os.PathLike,
                             rows: Sequence[Mapping[str, Any]]) -> Path:
    """Write ``<sweep>/pretrainings.parquet`` atomically (validated against
    experiment_pretrain), ordered by id."""
    import pyarrow.parquet as pq

    schema = get_schema(STAGES["pretrain"])
    ordered = sorted((dict(r) for r in rows), key=lambda r: str(r["pretrain_id"]))
    table = schema.validate(pa.Table.from_pylist(ordered, schema=schema.schema))
    path = SweepFolder(sweep_dir).pretrainings_table
    atomic_write_with(path, lambda tmp: pq.write_table(table, tmp))
    return path


def run_finetuning(ctx: SweepContext, job: PlannedRun,
                   pretrain: PretrainResult | None) -> dict[str, Any]:
    """Fine-tune and test one cell's run (or read it back); returns its experiment_runs row
    with ``status`` ``ok`` (computed now) or ``skipped`` (found in the store)."""
    st = open_store(ctx.store)
    out = SweepFolder(ctx.sweep_dir).run_dir(job.key)
    for _ in range(2):
        claim = _claim(ctx, job.key, lambda: st.exists("experiment_runs", job.key), out,
                       f"run {job.id}")
        if claim is not None:
            break
        try:
            row = st.read("experiment_runs", job.key).to_pylist()[0]
        except CorruptArtifactError:  # moved into quarantine by the read: compute it again
            continue
        return {**row, "sweep": ctx.name, "status": "skipped"}
    with claim:
        return _finetune(ctx, st, job, pretrain, out)


def _finetune(ctx: SweepContext, st, job: PlannedRun, pretrain: PretrainResult | None,
              out: Path) -> dict[str, Any]:
    from sim2radar.experiment.runner import finetune_and_test

    spec, real = job.spec, ctx.datasets["real"]
    cfg = condition_config(ctx.finetune_config, spec.condition)
    fields = finetune_and_test(
        cfg, _load(ctx, "real", spec.train_ids, cfg),
        _load(ctx, "real", real.ids([ctx.eval_split]), cfg), out, seed=spec.seed,
        epochs=spec.epochs, encoder_checkpoint=pretrain.checkpoint if pretrain else None,
        val_frames=_load(ctx, "real", real.ids([ctx.val_split]), cfg) if ctx.val_every else [],
        val_every=ctx.val_every, max_val_points=ctx.max_val_points, device=ctx.device)
    row = {**_base_row(ctx, job, pretrain), **fields, "status": "ok", "error": "",
           "checkpoint": os.path.relpath(out / SweepFolder.LAST_CHECKPOINT,
                                         Path(ctx.sweep_dir).parent),
           "finished_at": datetime.now(UTC).isoformat(timespec="seconds")}
    schema = get_schema("experiment_runs")
    table = schema.validate(pa.Table.from_pylist([row], schema=schema.schema))
    described = {k: v for k, v in job.model_dump(mode="json").items() if k != "train_ids"}
    st.write("experiment_runs", job.key, table, stage_version=EXPERIMENT_STAGE_VERSION,
             provenance={"inputs": {"real": real.key, "pretrain": row["pretrain_key"]},
                         "config": {"detector": ctx.finetune_config.model_dump(mode="json"),
                                    "spec": described},
                         "seed": spec.seed, "timings_s": {"run": float(row["wall_time_s"])},
                         "extra": {"sweep": ctx.name, "train_ids": list(spec.train_ids)}})
    return row


def _base_row(ctx: SweepContext, job: PlannedRun,
              pretrain: PretrainResult | None) -> dict[str, Any]:
    spec, n_sim = job.spec, pretrain.n_frames if pretrain else 0
    return {"sweep": ctx.name, "run_key": job.key, "condition": spec.condition,
            "fraction": float(spec.fraction), "n_real_frames": spec.n_real,
            "n_sim_frames": n_sim, "sim_real_ratio": n_sim / spec.n_real if pretrain else None,
            "trial": spec.trial, "seed": spec.seed,
            "pretrain_key": pretrain.key if pretrain else None}


def failed_row(ctx: SweepContext, job: PlannedRun, pretrain: PretrainResult | None,
               error: BaseException | str) -> dict[str, Any]:
    """The experiment_runs row of a run that failed (AP null, ``error`` set)."""
    text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
    row = {c: None for c in get_schema("experiment_runs").schema.names}
    row.update(_base_row(ctx, job, pretrain))
    row.update(epochs=job.spec.epochs, steps=0, history_epoch=[], history_loss=[],
               history_val_epoch=[], history_val_ap=[], wall_time_s=0.0, device="",
               checkpoint="", status="failed", error=text[:2000],
               finished_at=datetime.now(UTC).isoformat(timespec="seconds"))
    return row


def write_runs_table(sweep_dir: str | os.PathLike, rows: list[dict[str, Any]]) -> Path:
    """Write ``<sweep>/runs.parquet`` atomically (validated against experiment_runs)."""
    import pyarrow.parquet as pq

    schema = get_schema("experiment_runs")
    table = schema.validate(pa.Table.from_pylist(rows, schema=schema.schema))
    path = SweepFolder(sweep_dir).runs_table
    atomic_write_with(path, lambda tmp: pq.write_table(table, tmp))
    return path

