"""``sim2radar generate --captures DIR``: a lab's RGB capture folder -> a radar dataset, and
``sim2radar worlds captures``: a sample capture folder rendered from procedural worlds.

The folder layout is documented in :mod:`sim2radar.factory.captures`; the flow in
:mod:`sim2radar.flows.capture_dataset`. Prefect and the flows are imported inside the commands.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from sim2radar.cli._app import console as _console
from sim2radar.cli.worlds import worlds_app
from sim2radar.factory.spec import MAX_WORLDS

__all__ = ["generate_from_captures", "run_captures", "print_stage_table"]

def run_captures(captures: Path, *, store: str, dataset: str, settings: dict[str, Any],
                 export_dir: str | None, png_dir: Path | None, force: bool, workers: int,
                 dask_address: str | None, use_prefect: bool, verbose: bool,
                 show_progress: bool = True, retry_failed: bool = False) -> dict[str, Any]:
    """Run the capture flow (or its plain loop) with a progress bar; write BEV PNGs; return
    the summary (failures counted, never raised)."""
    if use_prefect:
        from sim2radar.cli.simulate import _prefect_env

        _prefect_env(verbose)
    from rich.progress import Progress

    from sim2radar.cli._app import export_folder_lock
    from sim2radar.cli._datasets import progress_columns
    from sim2radar.cli._jobs import run_job
    from sim2radar.factory.captures import CaptureSpec, find_captures
    from sim2radar.tasks.capture import CaptureRequest, capture_dataset

    n_scenes = len(find_captures(captures, warn=False))  # the flow warns once
    with export_folder_lock(export_dir), \
            Progress(*progress_columns(), disable=not show_progress, transient=False) as progress:
        bar = progress.add_task("starting" + (" Prefect" if use_prefect else ""), total=n_scenes)

        def on_scene(outcome) -> None:
            pts = ",".join(str(f.measured.get("n_points", {}).get("reconstructed", "-"))
                           for f in outcome.parts)
            progress.update(bar, advance=1,
                            description=f"{outcome.id}: {outcome.status} ({pts} pts)")

        import os
        from contextlib import nullcontext

        from sim2radar.cli._app import ServerWatch, quiet_recorded_failures
        quiet = nullcontext()
        if use_prefect:
            from sim2radar.flows.engine import STEP_NAMES

            quiet = quiet_recorded_failures(["capture-scene", *STEP_NAMES], verbose)
        request = CaptureRequest(
            captures=str(captures), spec=CaptureSpec(**settings), store=str(store),
            dataset=dataset, export_dir=None if export_dir is None else str(export_dir),
            force=force, retry_failed=retry_failed,
            run={"workers": workers, "dask_address": dask_address})

        def run(prefect: bool) -> dict[str, Any]:
            return run_job("sim2radar.flows.capture_dataset:capture_dataset", capture_dataset,
                           request, job="captures", use_prefect=prefect, on_outcome=on_scene)

        with quiet, ServerWatch(os.environ.get("PREFECT_API_URL") if use_prefect
                                else None) as watch:
            summary = watch.run(lambda: run(use_prefect), lambda: run(False),
                                lambda: progress.update(bar, completed=0,
                                                        description="without Prefect"))
    summary["pngs"] = []
    if png_dir is not None:
        from sim2radar.tasks.dataset import outcomes_from_summary, world_bev_pngs

        summary["pngs"] = world_bev_pngs(store, outcomes_from_summary(summary), png_dir,
                                         request.spec)
    return summary


def print_stage_table(summary: dict[str, Any]) -> None:
    """Seconds per step and scene (this run's wall time; a cached step takes milliseconds)."""
    from rich.table import Table

    rows = summary.get("stage_table") or []
    if not rows:
        return
    table = Table(title="capture scenes: seconds per step (this run)")
    cols = [c for c in rows[0] if c != "error"]
    for c in cols:
        table.add_column(c, justify="left" if c in ("scene", "status") else "right")
    for r in rows:
        table.add_row(*("-" if r[c] is None else str(r[c]) for c in cols))
    _console().print(table)


@worlds_app.command("captures")
def worlds_captures(
    out: Path = typer.Option(Path("out/captures"), "--out", "-o",
                             help="Capture folder to write (one sub-folder per scene)."),
    worlds: int = typer.Option(5, "--worlds", "-n", min=1, max=MAX_WORLDS, help="Scenes (one per world seed)."),
    first_seed: int = typer.Option(0, help="Seed of the first world."),
    width: int = typer.Option(320, help="Image width [px]."),
    height: int = typer.Option(240, help="Image height [px]."),
    spp: int = typer.Option(16, help="RGB samples per pixel."),
    no_lidar: bool = typer.Option(False, "--no-lidar", help="Write no lidar.npy."),
    views: int = typer.Option(0, "--views", min=0, help="Earlier views per scene (views/ + "
                              "poses.txt), fused into its reconstruction."),
) -> None:
    """Write a sample capture folder rendered from procedural worlds (RGB + intrinsics with
    the rig calibration + LiDAR; no ground truth), the layout `generate --captures` reads."""
    from sim2radar.factory.captures import write_capture_folder

    if worlds < 1:
        typer.secho("error: --worlds must be >= 1", fg="red", err=True)
        raise typer.Exit(2)
    folders = write_capture_folder(out, range(first_seed, first_seed + worlds),
                                   rig={"width": width, "height": height, "spp": spp},
                                   lidar=not no_lidar, views=views)
    typer.echo(f"wrote {len(folders)} capture scene(s) to {out}")


def generate_from_captures(captures: Path, *, config: Path | None, out: str,
                           dataset: str | None, frames: int | None, radar: str | None,
                           reconstruction: str | None, seed: int | None,
                           export_openpcdet: Path | None, png_dir: Path | None, no_png: bool,
                           force: bool, strict: bool, workers: int, dask: str | None,
                           allow_failures: bool = False,
                           no_prefect: bool, json_out: Path | None, verbose: bool,
                           procedural: dict[str, Any], retry_failed: bool = False) -> None:
    """The ``generate --captures`` branch: validate everything (exit 2 naming the file and
    field), run, print the summary and the seconds per step, exit 1 when a scene failed (unless
    ``allow_failures``) or, under ``--strict``, a material fell back."""
    from sim2radar.cli._datasets import finish_generate
    from sim2radar.cli.simulate import _default_png_dir
    from sim2radar.factory.spec import load_generate_config

    try:
        given = [name for name, v in procedural.items() if v is not None]
        if given:
            raise ValueError(f"{given} describe procedural worlds; drop them with --captures")
        if workers < 1:
            raise ValueError(f"--workers must be >= 1, got {workers}")
        cfg = load_generate_config(config) if config is not None else {}
        from sim2radar.factory.captures import CaptureSpec, capture_settings, find_captures

        settings = capture_settings(cfg, config, frames=frames, radar=radar,
                                    reconstruction=reconstruction, seed=seed)

        capture_spec = CaptureSpec(**settings)  # every field checked before any work
        find_captures(captures, warn=False)  # the flow lists it again and warns once
        from sim2radar.cli._datasets import preflight

        preflight(capture_spec.reconstruction)
        if dask:
            from sim2radar.cli.simulate import _prefect_env
            from sim2radar.flows.runners import task_runner

            _prefect_env(verbose)  # before Prefect is imported

            task_runner(workers, dask)
    except (ValueError, FileNotFoundError, ImportError) as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    if png_dir is None and not no_png:
        png_dir = _default_png_dir(out)
    summary = run_captures(
        captures, store=out, dataset=dataset or cfg.get("dataset", "captures"),
        settings=settings, export_dir=None if export_openpcdet is None else str(export_openpcdet),
        png_dir=None if no_png else png_dir, force=force, workers=workers, dask_address=dask,
        use_prefect=not no_prefect, verbose=verbose, retry_failed=retry_failed)
    print_stage_table(summary)
    finish_generate(summary, json_out, strict, allow_failures)
