"""``sim2radar sweep``: the paper's experiment grid as a resumable sweep.

    sim2radar sweep data/sim data/proxy_real --profile demo --name demo --out out/sweeps
    sim2radar sweep data/sim data/ifr --profile paper --name ifr     # a GPU or a cluster
    sim2radar sweep store:demo store:reference --profile smoke --name s --store out/store
    sim2radar sweep data/sim data/ifr --profile paper --plan --plan-workers 1,8   # cost only
    sim2radar sweep data/sim data/proxy_real --profile diagnosis --name diagnosis \
        --sim-gt data/sim_gt --ref data/ref_on_sim                 # the diagnosis arms
    sim2radar sweep-report docs/results/diagnosis      # rebuild results.md + dashboard.html
    sim2radar sweep data/sim data/proxy_real --name demo --mlflow sqlite:///mlflow.db  # + MLflow
    sim2radar sweep-report out/sweeps/demo --mlflow http://tracker:5000   # (re)log to MLflow

Prefect and torch are imported inside the command, so ``sim2radar --help`` stays fast.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from sim2radar.cli._app import app, exit_unless_writable, exit_unless_writable_outputs
from sim2radar.cli._app import console as _console
from sim2radar.experiment.folder import SweepFolder

__all__ = ["sweep", "sweep_report", "publish_sweep", "run_sweep", "sweep_datasets",
           "condition_overrides", "print_sweep_summary", "print_plan", "PUBLISHED_FILES",
           "SWEEP_FLAGS", "sweep_flag", "error_text"]


#: the MLflow options ``sweep`` and ``sweep-report`` share (beside their own ``--mlflow``)
MlflowExperiment = Annotated[str | None, typer.Option(
    "--mlflow-experiment", help="With --mlflow: the experiment (default: the sweep's name).")]
MlflowCheckpoints = Annotated[bool, typer.Option(
    "--mlflow-checkpoints", help="With --mlflow: also upload each run's last.pt.")]

#: ``sim2radar sweep``'s option for each setting the library's errors name
#: (:class:`~sim2radar.experiment.errors.SettingError`); datasets: :func:`sweep_flag`
SWEEP_FLAGS = {"name": "--name", "out": "--out", "preregistration": "--preregistration",
               "force": "--force-run", "runs_per_gpu": "--runs-per-gpu", "workers": "--workers",
               "mlflow_experiment": "--mlflow-experiment"}
#: the dataset options that are shorthands of ``--dataset ROLE=PATH``
DATASET_SHORTHANDS = ("--sim-gt", "--sim-one-material", "--ref")


def sweep_flag(setting: str) -> str | None:
    """How ``sim2radar sweep`` spells a library setting: its option (:data:`SWEEP_FLAGS`), a
    dataset role's shorthand option (``--sim-gt``: the registry's
    :attr:`~sim2radar.experiment.profiles.Condition.flag`), SIM / REAL, or ``--dataset
    ROLE=PATH`` for a role without one; None for a setting the command has no option for."""
    if not setting.startswith("dataset:"):
        return SWEEP_FLAGS.get(setting)
    from sim2radar.experiment.profiles import CONDITIONS

    role = setting.partition(":")[2]
    if role in ("sim", "real"):
        return role.upper()
    flag = next((c.flag for c in CONDITIONS.values() if c.sim_role == role), None)
    return flag if flag in DATASET_SHORTHANDS else f"--dataset {role}=PATH"


def error_text(exc: BaseException) -> str:
    """An error's message as the command line reports it: the settings a library
    :class:`~sim2radar.experiment.errors.SettingError` names spelled as this command's
    options (:func:`sweep_flag`)."""
    from sim2radar.experiment.errors import SettingError

    return exc.spelled(sweep_flag) if isinstance(exc, SettingError) else str(exc)


def _fractions(text: str | None) -> list[float] | None:
    if text is None:
        return None
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--fractions: expected comma-separated numbers such as "
                         f"0.05,0.1,0.25, got {text!r}") from None


def _ints(text: str, flag: str) -> tuple[int, ...]:
    try:
        values = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        values = ()
    if not values or min(values) < 1:
        raise ValueError(f"{flag}: expected comma-separated positive integers such as 1,8, "
                         f"got {text!r}")
    return values


def _step_seconds(text: str | None) -> dict[str, float] | None:
    if text is None:
        return None
    try:
        pre, ft = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--step-seconds: expected PRE,FT seconds per step such as 0.05,0.04, "
                         f"got {text!r}") from None
    if pre <= 0 or ft <= 0:
        raise ValueError(f"--step-seconds: seconds per step must be > 0, got {text!r}")
    return {"pretrain": pre, "finetune": ft}


def print_plan(cost: dict[str, Any]) -> None:
    """The grid's jobs, steps, seconds per step and expected wall times."""
    from rich.table import Table

    console = _console()
    how = "measured here" if cost["measured"] else "given"
    table = Table(title=f"sweep plan: profile {cost['profile']}, device {cost['device']}, "
                  f"mixed precision {cost['precision']['finetune']}")
    for col in ("jobs", "count", "optimiser steps", f"s/step ({how})", "compute [h]"):
        table.add_column(col, justify="right")
    for kind in ("pretrain", "finetune"):
        j = cost["jobs"][kind]
        if not j["jobs"]:
            continue
        sec = cost["step_seconds"][kind]
        table.add_row(kind, str(j["jobs"]), f"{j['steps']:,}", f"{sec:.3f}",
                      f"{j['steps'] * sec / 3600:.2f}")
    console.print(table)
    console.print(f"compute: {cost['compute_hours']:.2f} h of training steps (validation, "
                  "tests and start-up not included)")
    for n, hours in cost["wall_hours"].items():
        console.print(f"expected wall time on {n} worker(s), one run each: {hours:.2f} h")


def condition_overrides(text: str | None) -> dict[str, list[str]]:
    """``--conditions baseline,sim-pretrain,ref-pretrain`` as profile overrides: the
    registered main conditions under ``conditions`` and the ablations under ``ablations``.

    Raises
    ------
    ValueError — an unknown name (listing the known ones) or no baseline.
    """
    from sim2radar.experiment.profiles import BASELINE, CONDITIONS

    if text is None:
        return {}
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in CONDITIONS]
    if unknown:
        raise ValueError(f"--conditions: unknown condition(s) {unknown}; known: "
                         f"{sorted(CONDITIONS)}")
    if BASELINE not in names:
        names.insert(0, BASELINE)
    return {"conditions": [n for n in names if not CONDITIONS[n].ablation],
            "ablations": [n for n in names if CONDITIONS[n].ablation]}


def sweep_datasets(sim: str, real: str, options: dict[str, str | None],
                   pairs: list[str] | None = None) -> dict[str, str]:
    """The sweep's datasets by role: SIM, REAL, each given dataset option (``--sim-gt``) of
    the condition registry (:attr:`sim2radar.experiment.profiles.Condition.flag`), and each
    ``--dataset ROLE=PATH`` pair, whose roles come from the registry as it is now
    (:func:`~sim2radar.experiment.profiles.dataset_roles`): a condition registered with a new
    role is run with ``--dataset ROLE=PATH``, no new option needed.

    Raises
    ------
    ValueError — an unknown option or role (listing the known roles), a pair without ``=``, a
    role given twice, or ``sim``/``real`` given as a pair (they are the SIM and REAL
    arguments).
    """
    from sim2radar.experiment.profiles import CONDITIONS, dataset_roles

    roles = {c.flag: c.sim_role for c in CONDITIONS.values() if c.flag}
    unknown = sorted(set(options) - set(roles))
    if unknown:
        raise ValueError(f"no condition takes the dataset option(s) {unknown}")
    out = {"sim": sim, "real": real,
           **{roles[flag]: path for flag, path in options.items() if path is not None}}
    known = [r for r in dataset_roles() if r not in ("sim", "real")]
    for pair in pairs or []:
        role, sep, path = pair.partition("=")
        role, path = role.strip(), path.strip()
        if not sep or not role or not path:
            raise ValueError(f"--dataset {pair!r}: expected ROLE=PATH, e.g. ref=data/ref")
        if role in ("sim", "real"):
            raise ValueError(f"--dataset {pair!r}: {role} is the {role.upper()} argument")
        if role not in known:
            raise ValueError(f"--dataset {pair!r}: no condition pre-trains on role {role!r}; "
                             f"known roles: {known}")
        if role in out:
            raise ValueError(f"--dataset {pair!r}: the {role} dataset is given twice")
        out[role] = path
    return out


def run_sweep(sim: str, real: str, *, profile: str, name: str, out: str, store: str,
              datasets: dict[str, str] | None = None,
              ablations: bool = False, overrides: dict[str, Any] | None = None,
              workers: int | None = None, dask_address: str | None = None,
              device: str | None = None, show_progress: bool = True,
              verbose: bool = False, force: list[str] | None = None,
              mlflow: str | None = None, mlflow_experiment: str | None = None,
              mlflow_checkpoints: bool = False,
              runs_per_gpu: int | str | None = None,
              use_prefect: bool = True) -> dict[str, Any]:
    """Prepare (validating every input first) and run a sweep with a progress bar; returns
    the job's summary. ``datasets``: the other conditions' datasets by role
    (``{"sim-gt": ...}``); ``use_prefect=False`` runs the training runs one after another
    in this process without Prefect (:class:`~sim2radar.tasks.runner.PlainRunner`).

    ``mlflow``: a tracking URI to log the sweep to
    (:class:`~sim2radar.experiment.tracking.SweepTracker`; experiment ``mlflow_experiment``,
    default the sweep's name): what the folder already holds before the flow starts, each run
    (and the pre-trainings before it) as it finishes, the statistics at the end under
    ``summary["mlflow"]``. A tracker failure is warned about once and the sweep goes on.
    Without MLflow installed it raises ImportError before anything runs."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from sim2radar.cli.simulate import _prefect_env

    if mlflow is not None:
        from sim2radar.experiment.tracking import require_mlflow

        require_mlflow()        # before any work: the extra is missing, say so now
    if use_prefect:
        _prefect_env(verbose)
    from sim2radar.tasks.sweep import SweepRequest, prepare
    from sim2radar.tasks.sweep import run_sweep as sweep_job

    request = SweepRequest(sim=str(sim), real=str(real), profile=str(profile), name=name,
                           out=str(out), store=str(store),
                           datasets={k: str(v) for k, v in (datasets or {}).items()
                                     if v is not None},
                           ablations=ablations, overrides=overrides, device=device,
                           force=list(force or ()), workers=workers,
                           dask_address=dask_address, runs_per_gpu=runs_per_gpu)
    plan = prepare(request)     # every input validated before any training
    request = request.model_copy(update={"plan_path": plan.plan_path})
    tracker = None
    if mlflow is not None:
        tracker = _Tracking(mlflow, plan.context.sweep_dir, mlflow_experiment or plan.name,
                            mlflow_checkpoints)
    columns = [TextColumn("[bold]sweep"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TextColumn("{task.description}")]
    with Progress(*columns, disable=not show_progress) as progress:
        bar = progress.add_task(f"{len(plan.pretrains)} pre-training(s), then runs",
                                total=len(plan.runs))

        def on_run(row: dict) -> None:
            ap = row.get("ap_3d_r40_iou03")
            shown = "failed" if row["status"] == "failed" else (
                f"{row['status']} AP {ap:.1f}" if ap is not None else row["status"])
            progress.update(bar, advance=1, description=f"{row['condition']} "
                            f"{100 * row['fraction']:g}% t{row['trial']}: {shown}")
            if tracker is not None:
                tracker.sync()      # runs.parquet holds the row by now

        from sim2radar.cli._jobs import run_job

        # failed runs: Failed in Prefect, summary here
        summary = run_job("sim2radar.flows.run_experiment:run_experiment", sweep_job, request,
                          job="sweep", use_prefect=use_prefect, on_outcome=on_run)
    if tracker is not None:
        tracker.sync(final=True)
        summary = {**summary, "mlflow": tracker.summary()}
    return summary


class _Tracking:
    """A sweep's MLflow logging from the command line: a
    :class:`~sim2radar.experiment.tracking.SweepTracker` that warns once (in yellow, on
    stderr) and lets the sweep go on when the tracker fails, counting what it logged."""

    def __init__(self, uri: str, sweep_dir: str, experiment: str, checkpoints: bool) -> None:
        from sim2radar.experiment.tracking import SweepTracker

        self.experiment, self.logged = experiment, 0
        self.last = None
        self.tracker = SweepTracker(
            uri, sweep_dir, experiment=experiment, checkpoints=checkpoints, on_error="warn",
            warn=lambda msg: typer.secho(f"warning: {msg}", fg="yellow", err=True))
        self.sync()     # the parent run, and what a resumed sweep finished before

    def sync(self, final: bool = False) -> None:
        self.last = self.tracker.sync(final=final)
        self.logged += len(self.last.logged)

    def summary(self) -> dict[str, Any]:
        res = self.last
        return {"tracking_uri": self.tracker.uri, "experiment": self.experiment,
                "experiment_id": res.experiment_id, "parent_run_id": res.parent_run_id,
                "logged": self.logged, "error": res.error}


def print_sweep_summary(summary: dict[str, Any]) -> None:
    """Counts, the results table and where things went."""
    from rich.table import Table

    console = _console()
    c = summary["counts"]
    console.print(f"[bold]sweep {summary['name']}: runs {c['ok']} computed, {c['skipped']} "
                  f"cached, {c['failed']} failed[/bold]")
    stats = summary["stats"]
    table = Table(title=f"{stats['metric']} (mean ± std over trials); Δ vs baseline, 95 % CI")
    for col in ("condition", "real data", "n", "mean ± std", "Δ [95 % CI]", "p (Holm)",
                "verdict"):
        table.add_column(col)
    comp = {(x["condition"], x["fraction"]): x for x in stats["comparisons"]}

    def fmt(v, spec=".1f"):
        return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)

    for cell in stats["cells"]:
        x = comp.get((cell["condition"], cell["fraction"]))
        ci = "" if x is None else (f"{fmt(x['mean_diff'], '+.1f')} [{fmt(x['t_ci'][0])}, "
                                   f"{fmt(x['t_ci'][1])}]" if x["t_ci"] else
                                   fmt(x["mean_diff"], "+.1f"))
        table.add_row(cell["condition"], f"{100 * cell['fraction']:g}%", str(cell["n"]),
                      f"{fmt(cell['mean'])} ± {fmt(cell['std'])}", ci,
                      "" if x is None else fmt(x["p_holm"], ".3f"),
                      "" if x is None else x["verdict"])
    console.print(table)
    for x in sorted(stats.get("pooled") or [], key=lambda x: not x["primary"]):
        lo, hi = x["t_ci"]
        ci = f" [{fmt(lo, '+.1f')}, {fmt(hi, '+.1f')}]" if lo is not None else ""
        fr = ", ".join(f"{100 * f:g}%" for f in x["fractions"])
        console.print(f"{'PRIMARY' if x['primary'] else 'diagnostic'}: {x['condition']} vs "
                      f"baseline pooled over {fr}: Δ {fmt(x['mean_diff'], '+.1f')}{ci}, MDE "
                      f"{fmt(x['mde'])}, {x['n_pairs']} trials: {x['verdict']}")
    for s in (stats.get("pretrainings") or {}).get("summary", []):
        h, z = s["heldout"], s["zero_shot"]
        console.print(f"pre-trainings of {s['condition']} ({s['n']}, {s['n_failed']} failed): "
                      f"held-out sim AP {fmt(h['mean'])}, zero-shot real AP {fmt(z['mean'])}"
                      + ("" if s["threshold"] is None else
                         f"; threshold {s['threshold']:g} met by {s['n_met']}/{s['n']}"))
    console.print(f"results:   {summary['results_md']}")
    console.print(f"dashboard: {summary['dashboard']}")
    track = summary.get("mlflow")
    if track:
        console.print(f"mlflow:    {track['logged']} run(s) logged to experiment "
                      f"{track['experiment']!r} at {track['tracking_uri']} (sweep run "
                      f"{track['parent_run_id']})" if track["error"] is None else
                      f"mlflow:    logging stopped ({track['error']})", markup=False,
                      highlight=False)


@app.command()
def sweep(
    sim: str = typer.Argument(..., help="Simulated dataset: folder or store:NAME[:geometry]."),
    real: str = typer.Argument(..., help="Real dataset (measured, or the reference proxy)."),
    profile: str = typer.Option("demo", "--profile", "-p",
                                help="paper | study | demo | smoke or a profile YAML."),
    name: str = typer.Option("sweep", "--name", help="Sweep name (its folder under --out)."),
    out: Path = typer.Option(Path("out/sweeps"), "--out", "-o", help="Sweeps folder."),
    store: str = typer.Option("out/store", "--store", help="Artifact store (runs table)."),
    ablations: bool = typer.Option(False, "--ablations",
                                   help="Also run the ablation conditions."),
    sim_gt: str | None = typer.Option(None, "--sim-gt",
                                      help="Ground-truth-geometry sim dataset (ablation)."),
    sim_one_material: str | None = typer.Option(
        None, "--sim-one-material", help="One-material sim dataset (ablation)."),
    ref: str | None = typer.Option(
        None, "--ref", help="Reference radar on the sim worlds' ground truth (the ref-pretrain "
        "positive control)."),
    dataset: list[str] | None = typer.Option(
        None, "--dataset", help="ROLE=PATH: the dataset of the conditions that pre-train on "
        "ROLE (a role of the condition registry, e.g. ref, sim-gt); repeatable. --ref, --sim-gt "
        "and --sim-one-material are shorthands."),
    conditions: str | None = typer.Option(
        None, "--conditions", help="Override the profile's conditions, e.g. "
        "baseline,sim-pretrain,sim-gt-pretrain,ref-pretrain,sim-pretrain-lowlr."),
    preregistration: Path | None = typer.Option(
        None, "--preregistration", help="The study's pre-registration (Markdown) when the "
        "profile's path does not resolve (e.g. an installed package)."),
    trials: int | None = typer.Option(None, help="Override the profile's trials."),
    fractions: str | None = typer.Option(None, help="Override the fractions, e.g. 0.1,0.5,1."),
    workers: int | None = typer.Option(None, help="Concurrent runs (default: the profile's)."),
    runs_per_gpu: str | None = typer.Option(
        None, "--runs-per-gpu", help="Training runs sharing each CUDA GPU at once, in separate "
        "processes: a count, or 'auto' (measured: aggregate steps/s of 1/2/4/8; recorded in "
        "sweep.json). With --dask tcp://..., tasks claim GPU_RUNS units: start each GPU worker "
        "with --resources GPU_RUNS=N."),
    dask: str | None = typer.Option(None, "--dask", help="Dask scheduler address or 'local'."),
    device: str | None = typer.Option(None, help="Torch device (cpu, cuda, cuda:1)."),
    json_out: Path | None = typer.Option(None, "--json", help="Also write the summary as JSON."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Show Prefect's logs."),
    plan: bool = typer.Option(False, "--plan", help="Print the grid's cost (steps x seconds "
                              "per step measured here) and wall time; run nothing."),
    plan_workers: str = typer.Option("1,8", "--plan-workers",
                                     help="With --plan: worker counts to estimate, e.g. 1,4,8."),
    step_seconds: str | None = typer.Option(
        None, "--step-seconds", help="With --plan: PRE,FT seconds per step to use instead of "
        "timing them here (e.g. a GPU's figures)."),
    force_run: list[str] | None = typer.Option(
        None, "--force-run", help="Redo this run from scratch (its id, e.g. "
        "sim-pretrain-f0.05-t2, or key); repeatable. Its row and checkpoints are moved "
        "aside, not deleted."),
    mlflow: str | None = typer.Option(
        None, "--mlflow", help="Also log every run and pre-training to MLflow at this tracking "
        "URI (sqlite:///mlflow.db, http://host:5000), as each finishes; needs "
        "pip install 'sim2radar[mlflow]'. A tracker failure warns once; the sweep goes on."),
    mlflow_experiment: MlflowExperiment = None,
    mlflow_checkpoints: MlflowCheckpoints = False,
    no_prefect: bool = typer.Option(
        False, "--no-prefect", help="Run the training runs one after another in this "
        "process, without the Prefect engine (no UI; the same folder, rows and results)."),
) -> None:
    """Run the experiment grid: baseline vs sim-pretrain (and ablations) over real-data
    fractions x trials, with paired statistics, a results table and a dashboard.

    Rerunning a sweep recomputes nothing that finished; a killed run resumes from its last
    checkpoint. Exit status 0, 1 when a run failed, 2 for bad arguments or inputs.
    """
    from sim2radar.datasets import DatasetError

    if mlflow is not None and not plan:
        from sim2radar.experiment.tracking import MlflowMissing, require_mlflow

        try:
            require_mlflow()      # up front: before any input is read or run trained
        except MlflowMissing as exc:
            typer.secho(f"error: --mlflow: {exc}", fg="red", err=True)
            raise typer.Exit(2) from None
    exit_unless_writable(store, "--store")
    if not plan:
        exit_unless_writable_outputs({"--out": out})
    exit_unless_writable_outputs({"--json": None if json_out is None else json_out.parent})
    overrides: dict[str, Any] = {}
    try:
        if workers is not None and workers < 1:
            raise ValueError(f"--workers must be >= 1, got {workers}")
        if no_prefect and (dask or runs_per_gpu is not None or (workers or 1) > 1):
            raise ValueError("--no-prefect runs one training run at a time in this process: "
                             "drop --dask, --runs-per-gpu and --workers")
        if runs_per_gpu is not None:
            from sim2radar.tasks.experiment import cuda_devices, parse_runs_per_gpu

            runs_per_gpu = parse_runs_per_gpu(runs_per_gpu)
            cuda_devices(device)        # a CUDA GPU, or exit 2 now
        if trials is not None:
            overrides["trials"] = trials
        fr = _fractions(fractions)
        if fr is not None:
            overrides["fractions"] = fr
        overrides.update(condition_overrides(conditions))
        if preregistration is not None:
            overrides["preregistration"] = preregistration.resolve()
        datasets = sweep_datasets(sim, real, {"--sim-gt": sim_gt,
                                              "--sim-one-material": sim_one_material,
                                              "--ref": ref}, dataset)
        if plan:
            from sim2radar.tasks.experiment import plan_cost

            cost = plan_cost(datasets, profile=profile, store=store, out=out,
                             ablations=ablations,
                             overrides=overrides or None, device=device,
                             workers=_ints(plan_workers, "--plan-workers"),
                             step_seconds=_step_seconds(step_seconds),
                             runs_per_gpu=runs_per_gpu)
            print_plan(cost)
            if json_out is not None:
                json_out.parent.mkdir(parents=True, exist_ok=True)
                json_out.write_text(json.dumps(cost, indent=1, default=str))
            return
        summary = run_sweep(sim, real, profile=profile, name=name, out=str(out), store=store,
                            datasets=datasets, ablations=ablations,
                            overrides=overrides or None, workers=workers, dask_address=dask,
                            device=device, verbose=verbose, force=force_run, mlflow=mlflow,
                            mlflow_experiment=mlflow_experiment,
                            mlflow_checkpoints=mlflow_checkpoints, runs_per_gpu=runs_per_gpu,
                            use_prefect=not no_prefect)
    except (ValueError, FileNotFoundError, DatasetError, ImportError) as exc:
        typer.secho(f"error: {error_text(exc)}", fg="red", err=True)
        raise typer.Exit(2) from None
    print_sweep_summary(summary)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(summary, indent=1, default=str))
    if summary["counts"]["failed"]:
        raise typer.Exit(1)


#: a published JSON file larger than this is kept gzip-compressed (``name.json.gz``) [bytes]
PUBLISH_GZIP_BYTES = 256 * 1024
#: a sweep folder's raw files a published study keeps (small; the checkpoints stay behind)
PUBLISHED_FILES = SweepFolder.PUBLISHED


def publish_sweep(folder: Path, dest: Path) -> list[str]:
    """Copy a sweep's raw files (:data:`PUBLISHED_FILES`) into ``dest`` (e.g.
    ``docs/results/<study>``). A pre-registration already in ``dest`` must be the one the sweep
    ran under (the same bytes): it was committed before the first run and is never replaced.

    Raises
    ------
    ValueError — the sweep's pre-registration differs from the one in ``dest``.
    """
    import gzip
    import shutil

    dest.mkdir(parents=True, exist_ok=True)
    copied = []
    for name in PUBLISHED_FILES:
        src = folder / name
        if not src.is_file() or src.resolve() == (dest / name).resolve():
            continue
        if name == SweepFolder.PREREGISTRATION and (dest / name).is_file():
            if (dest / name).read_bytes() != src.read_bytes():
                raise ValueError(f"{dest / name} differs from the pre-registration the sweep "
                                 f"ran under ({src}); a published pre-registration is never "
                                 "replaced: publish into another folder")
            continue
        data = src.read_bytes()
        if name.endswith(".json") and len(data) > PUBLISH_GZIP_BYTES:
            # a paper-sized plan (and sweep.json with its intensity matches) is megabytes of
            # repetitive JSON: kept compressed, byte-for-byte (mtime 0: the same file each time)
            (dest / (name + ".gz")).write_bytes(gzip.compress(data, mtime=0))
            (dest / name).unlink(missing_ok=True)
            copied.append(name + ".gz")
        else:
            shutil.copyfile(src, dest / name)
            (dest / (name + ".gz")).unlink(missing_ok=True)
            copied.append(name)
    return copied


@app.command("sweep-report")
def sweep_report(
    folder: Path = typer.Argument(..., help="A sweep folder, or a published one "
                                  "(docs/results/<study>/): sweep.json, runs.parquet and, when "
                                  "recorded, pretrainings.parquet."),
    publish: Path | None = typer.Option(
        None, "--publish", help="First copy the sweep's raw files (sweep.json, plan.json, "
        "runs.parquet, pretrainings.parquet, stats.json, the pre-registration) into this folder, "
        "e.g. docs/results/<study>, and write the report there."),
    mlflow: str | None = typer.Option(
        None, "--mlflow", help="Then log the sweep's runs, pre-trainings and results to MLflow "
        "at this tracking URI: only what it lacks (a sweep logged before adds nothing); needs "
        "pip install 'sim2radar[mlflow]'."),
    mlflow_experiment: MlflowExperiment = None,
    mlflow_checkpoints: MlflowCheckpoints = False,
) -> None:
    """Rebuild a sweep's stats.json, results.md and dashboard.html from its raw files (a
    finished sweep, or one published under docs/results/<study>/), and with --mlflow log it to
    MLflow. Trains nothing. Exit status 0, 1 when the MLflow tracker failed, 2 for bad
    input."""
    import pyarrow.parquet as pq

    from sim2radar.experiment.finish import write_results
    from sim2radar.experiment.tracking import MlflowMissing, TrackingError
    from sim2radar.fileio import json_text

    try:
        if mlflow is not None:
            from sim2radar.experiment.tracking import require_mlflow

            require_mlflow()      # up front: before any file is written
        for name in (SweepFolder.SWEEP, SweepFolder.RUNS):
            if json_text(folder / name) is None if name.endswith(".json") else \
                    not (folder / name).is_file():
                raise FileNotFoundError(f"{folder / name}: not found; a sweep folder holds "
                                        "sweep.json and runs.parquet (publish them with the "
                                        "sweep)")
        if publish is not None:
            exit_unless_writable_outputs({"--publish": publish.parent})
            copied = publish_sweep(folder, publish)
            typer.echo(f"published {', '.join(copied) or 'nothing new'} to {publish}")
            folder = publish
        layout = SweepFolder(folder)
        doc = layout.read_sweep_document()
        rows = pq.read_table(layout.runs_table).to_pylist()
        pre_path = layout.pretrainings_table
        pre = pq.read_table(pre_path).to_pylist() if pre_path.is_file() else []
        exit_unless_writable_outputs({"FOLDER": folder})
        res = write_results(folder, doc, rows, pre)
        if mlflow is not None:
            from sim2radar.experiment.tracking import SweepTracker

            tracker = SweepTracker(mlflow, folder, experiment=mlflow_experiment,
                                   checkpoints=mlflow_checkpoints)
            synced = tracker.sync(final=True)
    except TrackingError as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(1) from None
    except (ValueError, FileNotFoundError, KeyError, OSError, MlflowMissing) as exc:
        typer.secho(f"error: {'--mlflow: ' if isinstance(exc, MlflowMissing) else ''}{exc}",
                    fg="red", err=True)
        raise typer.Exit(2) from None
    typer.echo(f"results:   {res['results_md']}")
    typer.echo(f"dashboard: {res['dashboard']}")
    if mlflow is not None:
        typer.echo(f"mlflow:    {len(synced.logged)} run(s) logged ({len(synced.replaced)} "
                   f"replacing older ones), {synced.unchanged} already there; experiment "
                   f"{synced.experiment_id} at {tracker.uri}, sweep run {synced.parent_run_id}")
