"""``sim2radar worlds ...`` commands (procedural indoor worlds).

    sim2radar worlds preview --seed 3 --out preview.png      # contact sheet of one frame
    sim2radar worlds generate --worlds 4 --frames 8 --out out/store --dataset worlds-demo
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from sim2radar.cli._app import app, exit_unless_writable
from sim2radar.factory.spec import MAX_FRAMES_PER_WORLD, MAX_WORLDS

worlds_app = typer.Typer(
    rich_markup_mode=None, help="Procedural indoor worlds rendered by Mitsuba.", no_args_is_help=True)
app.add_typer(worlds_app, name="worlds")


def _configs(config: Path | None, width: int | None, height: int | None, spp: int | None):
    from sim2radar.worlds import WorldConfigError, load_worlds_config, make_rig_config

    try:
        if config is not None:
            world_cfg, rig = load_worlds_config(config)
        else:
            from sim2radar.worlds import RigConfig, WorldConfig

            world_cfg, rig = WorldConfig(), RigConfig()
        overrides = {k: v for k, v in (("width", width), ("height", height), ("spp", spp))
                     if v is not None}
        if overrides:
            rig = make_rig_config({**rig.model_dump(), **overrides}, source="command line")
    except WorldConfigError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    return world_cfg, rig


@worlds_app.command("preview")
def preview(
    seed: int = typer.Option(0, "--seed", min=0, help="World seed."),
    out: Path = typer.Option(Path("world_preview.png"), "--out", help="Contact-sheet PNG."),
    frame: int = typer.Option(0, "--frame", min=0, help="Frame index along the trajectory."),
    frames: int = typer.Option(6, "--frames", min=1, max=MAX_FRAMES_PER_WORLD, help="Trajectory length the frame is from."),
    config: Path | None = typer.Option(None, "--config", help="YAML with world:/rig: sections."),
    width: int | None = typer.Option(None, help="Image width [px] (default 640)."),
    height: int | None = typer.Option(None, help="Image height [px] (default 480)."),
    spp: int | None = typer.Option(None, help="Path-tracing samples per pixel (default 16)."),
) -> None:
    """Render one frame of a world and write a contact sheet: RGB, depth, semantic, material
    and a bird's-eye view with door boxes and the radar's field of view."""
    from sim2radar.worlds import generate_world, render_frame, trajectory
    from sim2radar.worlds.preview import contact_sheet

    if frame >= frames:
        typer.echo(f"error: --frame {frame} must be < --frames {frames}", err=True)
        raise typer.Exit(2)
    world_cfg, rig = _configs(config, width, height, spp)
    world = generate_world(seed, world_cfg)
    pose = trajectory(world, frames, seed=0)[frame]
    f = render_frame(world, pose, rig)
    contact_sheet(world, f, out, rig)
    n_vis = int(f.door_visible.sum())
    typer.echo(
        f"wrote {out}: seed {seed} ({world.layout}, {len(world.doors)} doors, {n_vis} visible), "
        f"render {f.timings_s['total_s']:.2f} s"
    )


@worlds_app.command("generate")
def generate(
    worlds: int = typer.Option(2, "--worlds", min=1, max=MAX_WORLDS, help="Number of worlds (seeds)."),
    frames: int = typer.Option(4, "--frames", min=1, max=MAX_FRAMES_PER_WORLD, help="Frames per world."),
    out: str = typer.Option("out/store", "--out", help="Artifact store root (path or URI)."),
    dataset: str = typer.Option("worlds", "--dataset", help="Manifest name."),
    first_seed: int = typer.Option(0, "--first-seed", min=0, help="Seed of the first world."),
    config: Path | None = typer.Option(None, "--config", help="YAML with world:/rig: sections."),
    width: int | None = typer.Option(None, help="Image width [px]."),
    height: int | None = typer.Option(None, help="Image height [px]."),
    spp: int | None = typer.Option(None, help="Samples per pixel."),
    force: bool = typer.Option(False, help="Recompute even when artifacts exist."),
    radar: str | None = typer.Option(
        None, "--radar", help="Also simulate radar point clouds per frame (preset or YAML)."),
    no_prefect: bool = typer.Option(False, "--no-prefect", help="Run without the Prefect engine."),
) -> None:
    """Generate N worlds x M frames into the artifact store (world specs, meshes, frames;
    with --radar also radar point clouds), with a manifest; cached by content key (a second
    run recomputes nothing)."""
    exit_unless_writable(out)
    world_cfg, rig = _configs(config, width, height, spp)
    seeds = list(range(first_seed, first_seed + worlds))
    from sim2radar.cli._jobs import run_job
    from sim2radar.tasks.worlds import WorldsRequest, generate_worlds

    request = WorldsRequest(seeds=seeds, n_frames=frames, store=str(out), dataset=dataset,
                            world=world_cfg, rig=rig, force=force, radar=radar)
    summary = run_job("sim2radar.flows.worlds:generate_worlds_flow", generate_worlds, request,
                      job="worlds", use_prefect=not no_prefect)
    typer.echo(json.dumps({k: summary[k] for k in ("store", "dataset", "counts")}, indent=1))
    if summary["counts"].get("failed"):
        for w in summary["outcomes"]:
            if w["status"] == "failed":
                typer.echo(f"world {w['id']} failed: {w['error']}", err=True)
        raise typer.Exit(1)
