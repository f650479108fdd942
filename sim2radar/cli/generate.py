"""``sim2radar generate``: the factory main job (procedural worlds -> radar frames + door boxes).

    sim2radar generate --worlds 4 --frames 8 --out out/store --geometry both \\
        --export-openpcdet out/openpcdet

Prefect and the flows are imported inside the command, so ``sim2radar --help`` stays fast.
A YAML file (``--config``, e.g. ``configs/generate/default.yaml``) may hold the same settings
(``worlds``, ``frames``, ``geometry``, ``radar``, ``reconstruction``, ``seed``, ``class_name``,
``world:`` and ``rig:`` sections); command-line options win over it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import typer

from sim2radar.cli._app import app, exit_unless_writable, exit_unless_writable_outputs
from sim2radar.factory.spec import label_range as _label_range
from sim2radar.factory.spec import load_generate_config

__all__ = ["generate", "load_generate_config", "print_generate_summary", "run_generate"]

def _progress_columns():
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn

    return [TextColumn("[bold]generate"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
            TextColumn("{task.description}")]


def _preflight(reconstruction) -> None:
    """A misconfigured VLM server stops the run before any work (ValueError, one line); an
    unreachable one is a warning (the run's retries and ``on_error`` handle it)."""
    from sim2radar.reconstruct.check import preflight_servers

    warning = preflight_servers(reconstruction)
    if warning:
        typer.secho(f"warning: {warning}", fg="yellow", err=True)


def run_generate(
    seeds: list[int],
    *,
    frames: int,
    store: str,
    dataset: str = "generated",
    geometry: str = "reconstructed",
    radar: Any = "ti-mmwcas",
    reconstruction: Any = None,
    world: Any = None,
    rig: Any = None,
    seed: int = 0,
    class_name: str = "door",
    labels: Any = None,
    material_override: str | None = None,
    export_label_range_m: Any = "detector",
    export_dir: str | None = None,
    png_dir: Path | None = None,
    force: bool = False,
    strict: bool = False,
    workers: int = 1,
    dask_address: str | None = None,
    use_prefect: bool = True,
    show_progress: bool = True,
    verbose: bool = False,
    render_rgb: bool = True,
    frames_by_seed: dict[int, int] | None = None,
    splits: dict[str, list[str]] | None = None,
    export_doppler: bool = False,
    domain: str | None = None,
    flow_name: str = "generate-dataset",
    export_whole_dataset: bool = False,
    motion: Any = None,
) -> dict[str, Any]:
    """Run the generate-dataset flow (or its plain loop) with a progress bar; write BEV PNGs.

    ``workers`` worlds run concurrently (threads); ``dask_address`` (a scheduler address such as
    ``tcp://127.0.0.1:8786``, or ``"local"`` for a LocalCluster of ``workers`` processes) runs
    them on Dask instead (needs ``prefect-dask``; not with ``use_prefect=False``).

    ``render_rgb``, ``frames_by_seed``, ``splits``, ``export_doppler``, ``domain``,
    ``flow_name`` and ``motion`` (the rig's speed range) serve the reference dataset
    (:mod:`sim2radar.flows.reference_dataset`).
    ``export_whole_dataset`` (``--retry-failed``): the export holds every frame the dataset's
    manifest lists, not only this run's worlds.

    Returns the flow's summary (``pngs`` added); failures are counted in it, never raised
    (with ``strict`` the Prefect run is marked failed; the CLI exits with status 1).
    """
    if dask_address and not use_prefect:
        raise ValueError("--dask needs the Prefect engine: drop --no-prefect")
    if use_prefect:  # before anything imports Prefect: its settings are read at import
        from sim2radar.cli.simulate import _prefect_env

        _prefect_env(verbose)
    from rich.progress import Progress

    from sim2radar.factory.spec import resolve_spec
    from sim2radar.tasks.dataset import generate_dataset_plain, world_bev_pngs

    spec = resolve_spec(frames, geometry, radar, reconstruction, world, rig, seed, class_name,
                        labels, material_override, _label_range(export_label_range_m),
                        render_rgb, motion)
    extras = {"frames_by_seed": frames_by_seed, "splits": splits,
              "export_doppler": export_doppler, "domain": domain}
    whole_export, export_dir = (export_dir, None) if export_whole_dataset else (None, export_dir)
    with Progress(*_progress_columns(), disable=not show_progress, transient=False) as progress:
        bar = progress.add_task("starting" + (" Prefect" if use_prefect else ""),
                                total=len(seeds))

        def on_world(outcome) -> None:
            pts = ",".join("/".join(str(v) for v in f.n_points.values()) or "-"
                           for f in outcome.frames)
            progress.update(bar, advance=1,
                            description=f"{outcome.world_id}: {outcome.status} ({pts} pts)")

        if use_prefect:
            from sim2radar.flows.generate_dataset import (
                DatasetFailures,
                generate_dataset_flow,
                progress_callback,
            )
            from sim2radar.tasks.runners import task_runner

            runner = task_runner(workers, dask_address)
            from sim2radar.cli._app import quiet_recorded_failures
            from sim2radar.flows._steps import STEP_NAMES

            with progress_callback(on_world), \
                    quiet_recorded_failures(["generate-world-dataset", *STEP_NAMES], verbose):
                try:
                    summary = generate_dataset_flow.with_options(
                        task_runner=runner, name=flow_name)(
                        seeds=seeds, spec=spec.to_dict(), store=store, dataset=dataset,
                        export_dir=export_dir, force=force, strict=strict, **extras)
                except DatasetFailures as exc:  # strict: the run is marked failed in Prefect
                    summary = exc.summary
        else:
            summary = generate_dataset_plain(seeds, spec, store, dataset, export_dir=export_dir,
                                             force=force, on_world=on_world, **extras)
    if whole_export is not None:
        from sim2radar.tasks.dataset import export_all, outcomes_from_manifest

        summary["export"] = export_all(store, outcomes_from_manifest(store, dataset),
                                       whole_export, spec, splits=splits,
                                       with_doppler=export_doppler, domain=domain)
    summary["pngs"] = []
    if png_dir is not None:
        from sim2radar.tasks.dataset import outcomes_from_summary

        summary["pngs"] = world_bev_pngs(store, outcomes_from_summary(summary), png_dir, spec)
    return summary


def _fmt(v: float, spec: str = ".1f") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def finish_generate(summary: dict[str, Any], json_out: Path | None, strict: bool) -> None:
    """The end of a generate-style command: print the summary, write it as JSON if asked, and
    exit with status 1 under ``--strict`` when a world or frame failed."""
    print_generate_summary(summary)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(summary, indent=1, default=str))
    if strict and summary["counts"]["failed"]:
        raise typer.Exit(1)


def print_generate_summary(summary: dict[str, Any]) -> None:
    """Human summary: counts, per-geometry table, seconds per stage, where things went."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = Console()
    c, fc = summary["counts"], summary["frame_counts"]
    console.print(
        f"[bold]{summary.get('unit', 'worlds')}: {c['ok']} computed, {c['skipped']} cached, "
        f"{c['failed']} failed; "
        f"frames: {fc['ok']} computed, {fc['skipped']} cached, {fc['failed']} failed[/bold] "
        f"— dataset {summary['dataset']!r}"
    )
    for w in summary["worlds"]:
        if w["status"] != "failed":
            continue
        # errors carry "[stage]" prefixes: escaped, or rich would take them for markup
        console.print(f"  [red]✗ {w['world_id']}[/red]: {escape(w['error'])}")
        for f in w["frames"]:
            if f["status"] == "failed":
                console.print(f"      [red]{f['frame_id']}[/red]: {escape(f['error'])}")
    table = Table(title="dataset summary (means per frame)")
    table.add_column("")
    geoms = list(summary["geometry"])
    for g in geoms:
        table.add_column(g, justify="right")
    rows = (("frames", "frames", "d"), ("radar points", "points_per_frame", ".1f"),
            ("door labels", "labels_per_frame", ".2f"),
            ("GT doors in radar view", "gt_doors_per_frame", ".2f"),
            ("frames with a label", "frac_frames_with_label", ".0%"),
            ("GT doors with radar points", "frac_gt_doors_with_points", ".0%"),
            ("label recall (3D IoU 0.3)", "label_recall", ".0%"),
            ("label precision (3D IoU 0.3)", "label_precision", ".0%"))
    for name, key, fmt in rows:
        if not summary.get("ground_truth", True) and ("GT" in name or "label_" in key):
            continue  # a capture folder has no ground truth to compare with
        table.add_row(name, *(_fmt(summary["geometry"][g][key], fmt) for g in geoms))
    console.print(table)
    secs = summary.get("seconds_per_frame", {})
    if secs:
        console.print("seconds per frame: " + ", ".join(f"{k} {_fmt(v, '.2f')}"
                                                        for k, v in secs.items()))
    comp = summary.get("comparison")
    if comp:
        console.print(f"reconstructed vs ground truth: points ratio {_fmt(comp['points_ratio'], '.2f')}, "
                      f"radar Chamfer {_fmt(comp['chamfer_m'], '.3f')} m")
    console.print(f"store:    {summary['store']}")
    console.print(f"manifest: {summary['manifest']}")
    for g, e in (summary.get("export") or {}).items():
        console.print(f"openpcdet \\[{g}]: {e['root']} ({e['frames']} frames, splits {e['splits']})")
        for w in e.get("warnings", []):
            console.print(f"  [yellow]warning:[/yellow] {escape(w)}")
    if summary.get("pngs"):
        console.print(f"pictures: {Path(summary['pngs'][0]).parent} ({len(summary['pngs'])} PNG)")


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
    export_openpcdet: Path | None = typer.Option(
        None, "--export-openpcdet", help="Also write the OpenPCDet custom layout here."),
    png_dir: Path | None = typer.Option(None, "--png-dir",
                                        help="BEV PNGs [default: OUT/../bev for local stores]."),
    no_png: bool = typer.Option(False, "--no-png", help="Do not write BEV PNGs."),
    force: bool = typer.Option(False, help="Recompute dataset frames even when cached."),
    strict: bool = typer.Option(False, help="Exit with status 1 if any world or frame failed."),
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
    the manifest; the others finish. Exit status: 0, or 1 with --strict when anything failed;
    2 for bad arguments or configs.
    """
    from sim2radar.cli.simulate import _default_png_dir, _prefect_env

    exit_unless_writable(out)
    exit_unless_writable_outputs({"--export-openpcdet": export_openpcdet,
                                  "--png-dir": None if no_png else png_dir,
                                  "--json": None if json_out is None else json_out.parent})
    for option, value in (("--frames", frames), ("--worlds", worlds)):
        if value is not None and value < 1:
            typer.secho(f"error: {option} must be >= 1, got {value}", fg="red", err=True)
            raise typer.Exit(2)
    if captures is not None:
        from sim2radar.cli.captures import generate_from_captures

        generate_from_captures(
            captures, config=config, out=out, dataset=dataset, frames=frames, radar=radar,
            reconstruction=reconstruction, seed=seed, export_openpcdet=export_openpcdet,
            png_dir=png_dir, no_png=no_png, force=force, strict=strict, workers=workers,
            dask=dask, no_prefect=no_prefect, json_out=json_out, verbose=verbose,
            retry_failed=retry_failed, procedural={"--worlds": worlds, "--first-seed": first_seed, "--geometry": geometry,
                        "--width": width, "--height": height, "--spp": spp,
                        "--material-override": material_override})
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
        if dask and no_prefect:
            raise ValueError("--dask needs the Prefect engine: drop --no-prefect")
        if dask:
            from sim2radar.tasks.runners import task_runner

            task_runner(workers, dask)  # prefect-dask installed, address well-formed
        params = dict(
            frames=int(frames if frames is not None else cfg.get("frames", 4)),
            geometry=geometry or cfg.get("geometry", "reconstructed"),
            radar=radar or cfg.get("radar", "ti-mmwcas"),
            reconstruction=reconstruction or cfg.get("reconstruction"),
            world=cfg.get("world"), rig=rig,
            seed=int(seed if seed is not None else cfg.get("seed", 0)),
            class_name=cfg.get("class_name", "door"),
            labels=cfg.get("labels"),
            material_override=material_override or cfg.get("material_override"),
            export_label_range_m=cfg.get("export_label_range_m", "detector"),
        )
        from sim2radar.factory.spec import resolve_spec

        # validate every config before any work (bad field -> exit 2 with its name)
        checked = resolve_spec(params["frames"], params["geometry"], params["radar"],
                               params["reconstruction"], params["world"], params["rig"],
                               params["seed"], params["class_name"], params["labels"],
                               params["material_override"],
                               _label_range(params["export_label_range_m"]))
        if "reconstructed" in checked.geometries:
            _preflight(checked.reconstruction)   # a misconfigured VLM server: exit 2 here
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
    summary = run_generate(
        seeds, store=out, dataset=dataset_name,
        export_dir=None if export_openpcdet is None else str(export_openpcdet),
        png_dir=None if no_png else png_dir, force=force, strict=strict, workers=workers,
        dask_address=dask, use_prefect=not no_prefect, verbose=verbose,
        export_whole_dataset=retry_failed, **params,
    )
    finish_generate(summary, json_out, strict)
