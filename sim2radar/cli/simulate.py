"""``sim2radar simulate``: scene files -> radar point clouds in the store.

Prefect and the flows are imported inside the commands, so ``sim2radar --help`` stays fast.
Prefect state goes to ``./.prefect`` unless ``PREFECT_HOME`` or ``PREFECT_API_URL`` is set
(then your own Prefect profile / server is used); flows report to the local server that
:mod:`sim2radar.cli.server` keeps running for that ``PREFECT_HOME``.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
from pathlib import Path
from typing import Any

import typer

from sim2radar.cli._app import (
    app,
    exit_unless_engine_fits,
    exit_unless_valid_dataset,
    exit_unless_writable,
    quiet_recorded_failures,
)
from sim2radar.cli._app import console as _console
from sim2radar.cli._datasets import ALLOW_FAILURES_HELP, exit_status
from sim2radar.configio import DEFAULT_RADAR


def _prefect_env(verbose: bool) -> None:
    """Project-local Prefect state, quiet logs and the managed local API server (started on
    first use, reused after), unless the user configured Prefect. Call before Prefect is
    imported."""
    from sim2radar.cli.server import use_managed_server

    if not os.environ.get("PREFECT_HOME") and not os.environ.get("PREFECT_API_URL"):
        os.environ["PREFECT_HOME"] = str(Path.cwd() / ".prefect")
    os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    # INFO goes to the API (the UI's run logs, sim2radar's own lines included); the console
    # shows warnings and errors unless --verbose
    os.environ.setdefault("PREFECT_LOGGING_LEVEL", "INFO")
    os.environ.setdefault("PREFECT_LOGGING_HANDLERS_CONSOLE_LEVEL",
                          "INFO" if verbose else "WARNING")
    os.environ.setdefault("PREFECT_LOGGING_EXTRA_LOGGERS", "sim2radar")
    os.environ.setdefault("PREFECT_LOGGING_TO_API_WHEN_MISSING_FLOW", "ignore")
    logging.getLogger("sim2radar").setLevel(logging.INFO)
    use_managed_server()


def run_scenes(
    scenes: list[Path],
    *,
    radar: str,
    store: str,
    dataset: str,
    png_dir: Path | None,
    seed: int = 0,
    force: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
    use_prefect: bool = True,
    show_progress: bool = True,
    verbose: bool = False,
) -> dict[str, Any]:
    """Simulate ``scenes`` with a progress bar (Prefect flow, or the plain loop); return the
    flow's summary. Failures are in the summary (never raised)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    scene_strs = [str(s) for s in scenes]
    columns = [
        TextColumn("[bold]simulate"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.description}"),
    ]
    with Progress(*columns, disable=not show_progress, transient=False) as progress:
        bar = progress.add_task("starting" + (" Prefect" if use_prefect else ""), total=len(scenes))

        def on_scene(outcome) -> None:
            pts = "/".join(str(n) for n in outcome.measured.get("n_points", [])) or "-"
            progress.update(bar, advance=1, description=f"{outcome.id}: {outcome.status} ({pts} pts)")

        from sim2radar.cli._jobs import run_job
        from sim2radar.tasks.radar import SimulateRequest, simulate_scenes

        request = SimulateRequest(
            scenes=scene_strs, radar=str(radar), store=str(store), dataset=dataset, seed=seed,
            png_dir=None if png_dir is None else str(png_dir), force=force,
            run={"workers": workers, "dask_address": dask_address if use_prefect else None})
        quiet = contextlib.nullcontext()
        if use_prefect:
            _prefect_env(verbose)
            import sim2radar.flows.simulate  # noqa: F401 - Prefect's logging set up first

            # a broken scene is recorded as failed and printed in the summary: no traceback
            quiet = quiet_recorded_failures(["simulate-scene"], verbose)
        with quiet:
            return run_job("sim2radar.flows.simulate:simulate_dataset", simulate_scenes, request,
                           job="simulate", use_prefect=use_prefect, on_outcome=on_scene)


def print_summary(summary: dict[str, Any], png_dir: Path | None) -> None:
    """Human summary: per scene status, points per frame, where artifacts and pictures went."""

    console = _console()
    counts = summary["counts"]
    console.print(
        f"[bold]{counts['ok']} computed, {counts['skipped']} cached (skipped), "
        f"{counts['failed']} failed[/bold] — radar {summary['radar']}, dataset {summary['dataset']!r}"
    )
    for s in summary["outcomes"]:
        if s["status"] == "failed":
            console.print(f"  [red]✗ {s['id']}[/red] ({s['source']}): {s['error']}")
            continue
        pts = s["measured"]["n_points"]
        mean = sum(pts) / len(pts) if pts else 0.0
        mark = "✓" if s["status"] == "ok" else "↺"
        console.print(
            f"  {mark} {s['id']}: {len(pts)} frame(s), points per frame {pts} "
            f"(mean {mean:.0f}) {'[dim](cached)[/dim]' if s['status'] == 'skipped' else ''}"
        )
        console.print(f"      points:   {s['measured']['locations'].get('radar_points', '')}")
    console.print(f"store:    {summary['store']}")
    console.print(f"manifest: {summary['manifest']}")
    if png_dir is not None:
        console.print(f"pictures: {png_dir}")


@app.command()
def simulate(
    scenes: list[str] = typer.Argument(
        ..., help="Scene YAML files, folders (all *.yaml inside) or globs: meshes + materials (+ radar_poses, boxes)."
    ),
    radar: str = typer.Option(DEFAULT_RADAR, "--radar", "-r", help="Radar preset name or YAML path."),
    out: str = typer.Option("out/store", "--out", "-o", help="Artifact store: folder or fsspec URI (s3://…)."),
    dataset: str = typer.Option("default", help="Manifest (dataset) name."),
    png_dir: Path | None = typer.Option(None, "--png-dir", help="Where to write BEV PNGs [default: OUT/../bev for local stores]."),
    no_png: bool = typer.Option(False, "--no-png", help="Do not write bird's-eye-view PNGs."),
    seed: int = typer.Option(0, help="Run seed (per-frame seeds derive from it)."),
    force: bool = typer.Option(False, help="Recompute even when the artifacts exist."),
    strict: bool = typer.Option(False, hidden=True, help="Kept for scripts: failures exit 1 "
                                "by default now."),
    allow_failures: bool = typer.Option(False, "--allow-failures", help=ALLOW_FAILURES_HELP),
    workers: int = typer.Option(1, help="Scenes simulated concurrently (threads)."),
    dask: str | None = typer.Option(None, help="Dask scheduler address, or 'local' (needs prefect-dask)."),
    no_prefect: bool = typer.Option(False, "--no-prefect", help="Run the plain loop without the Prefect engine."),
    json_out: Path | None = typer.Option(None, "--json", help="Also write the run summary as JSON."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Show Prefect's logs."),
) -> None:
    """Simulate radar point clouds for scene files into a Parquet store.

    One frame per radar pose of each scene; a second run with the same inputs recomputes
    nothing (content keys). Broken scenes are recorded as failed in the manifest; the others
    finish. Exit status: 0; 1 when a scene failed (as the Prefect run, which ends Failed;
    --allow-failures exits 0); 2 for bad arguments.
    """
    from sim2radar.radar import RadarConfigError, load_radar_config

    exit_unless_writable(out)
    exit_unless_valid_dataset(dataset)
    exit_unless_engine_fits(no_prefect, workers, dask)
    try:
        load_radar_config(radar)
    except RadarConfigError as exc:
        typer.secho(f"error: --radar: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    if png_dir is None and not no_png:
        png_dir = _default_png_dir(out)
    from sim2radar.scenes import expand_scenes

    try:
        scene_files = expand_scenes(scenes)
    except FileNotFoundError as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    summary = run_scenes(
        [Path(s) for s in scene_files],
        radar=radar,
        store=out,
        dataset=dataset,
        png_dir=None if no_png else png_dir,
        seed=seed,
        force=force,
        workers=workers,
        dask_address=dask,
        use_prefect=not no_prefect,
        verbose=verbose,
    )
    print_summary(summary, None if no_png else png_dir)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(summary, indent=1, default=str))
    if exit_status(summary, allow_failures=allow_failures, unit="scenes"):
        raise typer.Exit(1)


def _default_png_dir(out: str) -> Path | None:
    """``<store parent>/bev`` for a local store; None (no pictures) for remote stores."""
    if "://" in out and not out.startswith("file://"):
        return None
    return Path(out.removeprefix("file://")).resolve().parent / "bev"
