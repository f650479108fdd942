"""``sim2radar reference``: the reference ("proxy-real") radar dataset.

    sim2radar reference --out out/store --export-openpcdet data/proxy_real          # 618 frames
    sim2radar reference --worlds 12 --frames 6 --out out/store --export-openpcdet data/pr

The signal-level reference radar (preset ``ti-mmwcas-reference``) on the ground-truth geometry
of procedural worlds disjoint from the simulated domain's (seeds from 100000 by default), split
by world, exported in OpenPCDet's custom layout with ``dataset.json`` saying ``domain:
proxy-real (reference radar simulation)``. A measured dataset in the same layout replaces it in
every experiment with no code change.
"""

from __future__ import annotations

from pathlib import Path

import typer

from sim2radar.cli._app import (
    app,
    exit_unless_engine_fits,
    exit_unless_valid_dataset,
    exit_unless_writable,
    exit_unless_writable_outputs,
)
from sim2radar.cli._datasets import ALLOW_FAILURES_HELP
from sim2radar.factory.spec import MAX_FRAMES_PER_WORLD, MAX_WORLDS

__all__ = ["reference"]


@app.command()
def reference(
    worlds: int | None = typer.Option(
        None, "--worlds", "-n", min=1, max=MAX_WORLDS,
        help="Worlds of --frames frames each [default: sized like the paper, 371/92/155]."),
    frames: int = typer.Option(10, "--frames", "-m", min=1, max=MAX_FRAMES_PER_WORLD,
                               help="Frames per world."),
    out: str = typer.Option("out/store", "--out", "-o", help="Artifact store (folder or URI)."),
    export_openpcdet: Path | None = typer.Option(
        None, "--export-openpcdet", help="Write the dataset in OpenPCDet's layout here."),
    first_seed: int = typer.Option(
        100_000, help="Seed of the first world (keep disjoint from the simulated domain)."),
    radar: str = typer.Option("ti-mmwcas-reference", "--radar", "-r",
                              help="Reference radar preset or YAML (fidelity: signal)."),
    dataset: str = typer.Option("reference", help="Manifest (dataset) name."),
    seed: int = typer.Option(0, help="Run seed: trajectories, radar noise, world splits."),
    speed: tuple[float, float] = typer.Option(
        (0.5, 1.5), "--speed", help="The rig's walking speed range [m/s], drawn per frame "
        "(MIN MAX; 0 0 stands still): the Doppler of the points."),
    png_dir: Path | None = typer.Option(None, "--png-dir", help="BEV PNGs [default OUT/../bev]."),
    no_png: bool = typer.Option(False, "--no-png", help="Do not write BEV PNGs."),
    force: bool = typer.Option(False, help="Recompute frames even when cached."),
    strict: bool = typer.Option(False, hidden=True, help="Kept for scripts: failures exit 1 "
                                "by default now."),
    allow_failures: bool = typer.Option(False, "--allow-failures", help=ALLOW_FAILURES_HELP),
    workers: int = typer.Option(1, help="Worlds processed concurrently."),
    dask: str | None = typer.Option(None, "--dask", help="Dask scheduler address or 'local'."),
    no_prefect: bool = typer.Option(False, "--no-prefect", help="Plain loop without Prefect."),
    json_out: Path | None = typer.Option(None, "--json", help="Also write the summary as JSON."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Show Prefect's logs."),
) -> None:
    """Build the reference radar dataset: the labelled proxy for measured radar."""
    from sim2radar.cli.generate import finish_generate, run_generate
    from sim2radar.cli.simulate import _default_png_dir, _prefect_env
    from sim2radar.factory.reference import DOMAIN_LABEL

    exit_unless_writable(out)
    exit_unless_valid_dataset(dataset)
    exit_unless_writable_outputs({"--export-openpcdet": export_openpcdet,
                                  "--png-dir": None if no_png else png_dir,
                                  "--json": None if json_out is None else json_out.parent})
    exit_unless_engine_fits(no_prefect, workers, dask)
    if not no_prefect:
        _prefect_env(verbose)
    try:
        from sim2radar.tasks.reference import ReferenceRequest
        from sim2radar.tasks.runner import RunOptions

        if workers < 1:
            raise ValueError(f"--workers must be >= 1, got {workers}")
        request = ReferenceRequest(
            store=out, dataset=dataset, first_seed=first_seed, worlds=worlds,
            frames_per_world=frames, radar=radar, seed=seed, speed_mps=speed, force=force,
            strict=strict, run=RunOptions(workers=workers, dask_address=dask),
            export_dir=None if export_openpcdet is None else str(export_openpcdet))
        plan = request.plan()
        request.generate_request()  # the radar and spec validated here
    except (ValueError, FileNotFoundError, ImportError) as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    if png_dir is None and not no_png:
        png_dir = _default_png_dir(out)
    typer.echo(f"reference dataset: {len(plan.seeds)} worlds from seed {plan.seeds[0]}, "
               f"{plan.n_frames} frames, splits {plan.split_frames()} — {DOMAIN_LABEL}")
    summary = run_generate(request, png_dir=None if no_png else png_dir,
                           use_prefect=not no_prefect, verbose=verbose)
    finish_generate(summary, json_out, strict, allow_failures)
