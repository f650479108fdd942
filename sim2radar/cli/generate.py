"""``sim2radar generate``: the factory main job (procedural worlds -> radar frames + door boxes).

    sim2radar generate --worlds 4 --frames 8 --out out/store --geometry both \\
        --export-openpcdet out/openpcdet

Prefect and the flows are imported inside the command, so ``sim2radar --help`` stays fast.
A YAML file (``--config``, e.g. ``configs/generate/default.yaml``) may hold the same settings
(``worlds``, ``frames``, ``geometry``, ``radar``, ``reconstruction``, ``seed``, ``class_name``,
``motion: {speed_mps: [MIN, MAX]}``, ``world:`` and ``rig:`` sections); command-line options
win over it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import typer

from sim2radar.cli._app import (
    app,
    exit_unless_engine_fits,
    exit_unless_valid_dataset,
    exit_unless_writable,
    exit_unless_writable_outputs,
    export_folder_lock,
)
from sim2radar.cli._datasets import (
    ALLOW_FAILURES_HELP,
    finish_generate,
    preflight,
    print_generate_summary,
    progress_columns,
)
from sim2radar.factory.spec import (
    DEFAULT_RADAR,
    MAX_FRAMES_PER_WORLD,
    MAX_WORLDS,
    DatasetSpec,
    load_generate_config,
)
from sim2radar.tasks.generate import GenerateRequest, generate_dataset
from sim2radar.tasks.reference import ReferenceRequest

__all__ = ["generate", "load_generate_config", "print_generate_summary", "run_generate"]


def run_generate(request: GenerateRequest | ReferenceRequest, *,
                 png_dir: Path | None = None, use_prefect: bool = True,
                 show_progress: bool = True, verbose: bool = False) -> dict[str, Any]:
    """Run the ``generate`` job (or the ``reference`` job, for a
    :class:`~sim2radar.tasks.reference.ReferenceRequest`) with a progress bar, holding the
    export folder's writer lock (:func:`sim2radar.fileio.writer_lock`: a second run exporting
    to the same folder is refused while this one runs); write BEV PNGs.

    With ``use_prefect`` the job's flow runs (worlds on ``request.run``'s threads or Dask
    cluster; if the Prefect server stops answering the run goes on without it); otherwise the
    driver with a plain runner.

    Returns the job's summary (``pngs`` added); failures are counted in it, never raised
    (with ``strict`` the Prefect run is marked failed; the CLI exits with status 1).
    """
    if request.run.dask_address and not use_prefect:
        raise ValueError("--dask needs the Prefect engine: drop --no-prefect")
    if use_prefect:  # before anything imports Prefect: its settings are read at import
        from sim2radar.cli.simulate import _prefect_env

        _prefect_env(verbose)
    from rich.progress import Progress

    from sim2radar.cli._jobs import run_job
    from sim2radar.tasks.dataset import world_bev_pngs
    from sim2radar.tasks.generate import DatasetFailures
    from sim2radar.tasks.reference import reference_dataset

    generate = request if isinstance(request, GenerateRequest) else request.generate_request()
    export_dir = generate.export_dir
    if isinstance(request, GenerateRequest):
        flow, driver = "sim2radar.flows.generate_dataset:generate_dataset", generate_dataset
    else:
        flow, driver = "sim2radar.flows.reference_dataset:reference_dataset", reference_dataset
    with export_folder_lock(export_dir), \
            Progress(*progress_columns(), disable=not show_progress, transient=False) as progress:
        bar = progress.add_task("starting" + (" Prefect" if use_prefect else ""),
                                total=len(generate.seeds))

        def on_world(outcome) -> None:
            pts = ",".join("/".join(str(v) for v in f.measured.get("n_points", {}).values())
                           or "-" for f in outcome.parts)
            progress.update(bar, advance=1,
                            description=f"{outcome.id}: {outcome.status} ({pts} pts)")

        def run(prefect: bool) -> dict[str, Any]:
            try:   # failed worlds: Failed in Prefect, summary here
                return run_job(flow, driver, request, job="generate", use_prefect=prefect,
                               on_outcome=on_world)
            except DatasetFailures as exc:  # strict: the run is marked failed in Prefect
                return exc.summary

        if use_prefect:
            from sim2radar.cli._app import ServerWatch, quiet_recorded_failures
            from sim2radar.flows.engine import STEP_NAMES

            with quiet_recorded_failures(["generate-world-dataset", *STEP_NAMES], verbose), \
                    ServerWatch(os.environ.get("PREFECT_API_URL")) as watch:
                summary = watch.run(
                    lambda: run(True), lambda: run(False),
                    lambda: progress.update(bar, completed=0, description="without Prefect"))
        else:
            summary = run(False)
    summary["pngs"] = []
    if png_dir is not None:
        from sim2radar.tasks.dataset import outcomes_from_summary

        summary["pngs"] = world_bev_pngs(generate.store, outcomes_from_summary(summary),
                                         png_dir, generate.spec)
    return summary


@app.command()
def generate(
    captures: Path | None = typer.Option(
        None, "--captures", help="A capture folder of RGB scenes (rgb.png + intrinsics.yaml "
        "[+ lidar.npy] per sub-folder) instead of procedural worlds; --frames = radar poses "
        "per scene."),
    worlds: int | None = typer.Option(None, "--worlds", "-n", help="Number of worlds [default 4]."),
    frames: int | None = typer.Option(None, "--frames", "-m", help="Frames per world [default 4]."),
    out: str = typer.Option("out/store", "--out", "-o",
                            help="Artifact store: folder or fsspec URI (s3://…)."),
    geometry: str | None = typer.Option(
        None, "--geometry", "-g",
        help="reconstructed (paper pipeline, default) | ground_truth | both."),
    radar: str | None = typer.Option(None, "--radar", "-r",
                                     help="Radar preset name or YAML path [ti-mmwcas]."),
    reconstruction: str | None = typer.Option(
        None, "--reconstruction",
        help="Reconstruction preset (builtin, oracle, builtin-oracle-depth) or YAML path."),
    config: Path | None = typer.Option(None, "--config", "-c",
                                       help="Generate YAML (see configs/generate/)."),
    first_seed: int | None = typer.Option(None, help="Seed of the first world [0]."),
    seed: int | None = typer.Option(None, help="Run seed: trajectories, radar noise, splits [0]."),
    dataset: str | None = typer.Option(None, help="Manifest (dataset) name [generated]."),
    width: int | None = typer.Option(None, help="Override the camera width [px]."),
    height: int | None = typer.Option(None, help="Override the camera height [px]."),
    spp: int | None = typer.Option(None, help="Override RGB samples per pixel."),
    material_override: str | None = typer.Option(
        None, "--material-override",
        help="Simulate every mesh as this material (the one-material ablation)."),
    speed: tuple[float, float] | None = typer.Option(
        None, "--speed", help="The rig's walking speed range [m/s], drawn per frame (MIN MAX; "
        "0 0 stands still) [0.5 1.5]: Doppler of the reference radar, Doppler bins of the "
        "ray tracer's detector."),
    export_openpcdet: Path | None = typer.Option(
        None, "--export-openpcdet", help="Also write the OpenPCDet custom layout here."),
    png_dir: Path | None = typer.Option(None, "--png-dir",
                                        help="BEV PNGs [default: OUT/../bev for local stores]."),
    no_png: bool = typer.Option(False, "--no-png", help="Do not write BEV PNGs."),
    force: bool = typer.Option(False, help="Recompute dataset frames even when cached."),
    strict: bool = typer.Option(False, help="Also exit with status 1 when a material fell back "
                                "to unknown (a VLM outage)."),
    allow_failures: bool = typer.Option(False, "--allow-failures", help=ALLOW_FAILURES_HELP),
    workers: int = typer.Option(1, help="Worlds processed concurrently (threads, or processes "
                                "with --dask local)."),
    dask: str | None = typer.Option(
        None, "--dask", help="Run worlds on Dask: scheduler address (tcp://127.0.0.1:8786) or "
        "'local' (LocalCluster of --workers processes); needs prefect-dask."),
    no_prefect: bool = typer.Option(False, "--no-prefect",
                                    help="Run the plain loop without the Prefect engine."),
    json_out: Path | None = typer.Option(None, "--json", help="Also write the summary as JSON."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Show Prefect's logs."),
    retry_failed: bool = typer.Option(
        False, "--retry-failed", help="Rerun only the worlds (capture scenes) the dataset's "
        "manifest records as failed (same --config/options as the first run); the export "
        "covers the whole dataset."),
) -> None:
    """Generate a radar dataset from procedural worlds: render, reconstruct (or use the
    ground-truth geometry), simulate the radar, store points + door boxes, export.

    A second run with the same inputs recomputes nothing. Failed worlds/frames are recorded in
    the manifest; the others finish. A material that fell back to ``unknown`` (VLM
    ``on_error: unknown``) is counted in the summary and manifest and its frames are made again
    by the next run. Exit status: 0; 1 when a world or frame failed (as the Prefect run, which
    ends Failed; --allow-failures exits 0) or, with --strict, a material fell back; 2 for bad
    arguments or configs.
    """
    from sim2radar.cli.simulate import _default_png_dir, _prefect_env

    exit_unless_writable(out)
    exit_unless_valid_dataset(dataset)
    exit_unless_writable_outputs({"--export-openpcdet": export_openpcdet,
                                  "--png-dir": None if no_png else png_dir,
                                  "--json": None if json_out is None else json_out.parent})
    exit_unless_engine_fits(no_prefect, workers, dask)
    for option, value, most in (("--frames", frames, MAX_FRAMES_PER_WORLD),
                                ("--worlds", worlds, MAX_WORLDS)):
        if value is not None and not 1 <= value <= most:
            typer.secho(f"error: {option} must be between 1 and {most}, got {value}",
                        fg="red", err=True)
            raise typer.Exit(2)
    if captures is not None:
        from sim2radar.cli.captures import generate_from_captures

        generate_from_captures(
            captures, config=config, out=out, dataset=dataset, frames=frames, radar=radar,
            reconstruction=reconstruction, seed=seed, export_openpcdet=export_openpcdet,
            png_dir=png_dir, no_png=no_png, force=force, strict=strict,
            allow_failures=allow_failures, workers=workers, dask=dask, no_prefect=no_prefect, json_out=json_out, verbose=verbose,
            retry_failed=retry_failed, procedural={
                "--worlds": worlds, "--first-seed": first_seed, "--geometry": geometry,
                "--width": width, "--height": height, "--spp": spp,
                "--material-override": material_override, "--speed": speed})
        return
    if not no_prefect:
        _prefect_env(verbose)  # before the config check below imports Prefect
    try:
        cfg = load_generate_config(config) if config is not None else {}
        rig = dict(cfg.get("rig") or {})
        rig.update({k: v for k, v in (("width", width), ("height", height), ("spp", spp))
                    if v is not None})
        n_worlds = int(worlds if worlds is not None else cfg.get("worlds", 4))
        first = int(first_seed if first_seed is not None else cfg.get("first_seed", 0))
        if n_worlds < 1:
            raise ValueError(f"--worlds must be >= 1, got {n_worlds}")
        if workers < 1:
            raise ValueError(f"--workers must be >= 1, got {workers}")
        if dask:
            from sim2radar.flows.runners import task_runner

            task_runner(workers, dask)  # prefect-dask installed, address well-formed
        from sim2radar.tasks.runner import RunOptions

        run_options = RunOptions(workers=workers, dask_address=dask)
        # every config validated before any work (bad field -> exit 2 with its name)
        spec = DatasetSpec.model_validate({
            "frames_per_world": int(frames if frames is not None else cfg.get("frames", 4)),
            "geometry": geometry or cfg.get("geometry", "reconstructed"),
            "radar": radar or cfg.get("radar", DEFAULT_RADAR),
            "reconstruction": reconstruction or cfg.get("reconstruction"),
            "world": cfg.get("world"), "rig": rig,
            "seed": int(seed if seed is not None else cfg.get("seed", 0)),
            "class_name": cfg.get("class_name", "door"),
            "labels": cfg.get("labels"),
            "material_override": material_override or cfg.get("material_override"),
            "export_label_range_m": cfg.get("export_label_range_m", "detector"),
            **({"motion": {"speed_mps": list(speed)}} if speed is not None
               else {"motion": cfg["motion"]} if "motion" in cfg else {}),
        })
        if "reconstructed" in spec.geometries:
            preflight(spec.reconstruction)   # a misconfigured VLM server: exit 2 here
        dataset_name = dataset or cfg.get("dataset", "generated")
        seeds = list(range(first, first + n_worlds))
        if retry_failed:
            from sim2radar.tasks.dataset import failed_world_seeds

            seeds = failed_world_seeds(out, dataset_name)
    except (ValueError, FileNotFoundError, ImportError) as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    if retry_failed and not seeds:
        typer.echo(f"dataset {dataset_name!r}: no world is recorded as failed; nothing to retry")
        return
    if png_dir is None and not no_png:
        png_dir = _default_png_dir(out)
    request = GenerateRequest(
        spec=spec, seeds=seeds, store=out, dataset=dataset_name,
        export_dir=None if export_openpcdet is None else str(export_openpcdet), force=force,
        strict=strict, run=run_options, export_manifest=retry_failed)
    summary = run_generate(request, png_dir=None if no_png else png_dir,
                           use_prefect=not no_prefect, verbose=verbose)
    finish_generate(summary, json_out, strict, allow_failures)
