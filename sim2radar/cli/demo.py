"""``sim2radar demo``: the whole mission on the built-in default, no weights, no GPU.

    make demo                       # = sim2radar demo --out out

1. **Simulated domain** — procedural worlds (seeds 0..n-1) rendered, reconstructed with the
   built-in backends and simulated with the ray tracer (the paper's pipeline), plus the same
   frames on the ground-truth geometry (``out/openpcdet/{reconstructed,ground_truth}``).
2. **"Real" domain** — the reference radar (signal-level FMCW MIMO simulation) on the
   ground-truth geometry of *other* worlds (seeds from 100000): ``out/openpcdet/proxy_real``,
   labelled ``proxy-real (reference radar simulation)`` everywhere.
3. **Sim–real gap** — the reference radar on the simulated domain's own frames
   (``out/openpcdet/proxy_real_paired``) compared with the ray-traced frames: points per frame,
   coverage, intensities, Chamfer distance, an overlay picture.
4. **Experiment sweep** — the ``demo`` profile: baseline vs sim-pretrain over 5 fractions x 3
   trials, paired statistics, ``results.md``.
5. **Dashboard** — ``out/sweeps/demo/dashboard.html`` (offline; ``sim2radar dashboard
   out/sweeps/demo --serve`` to watch a sweep live).

Everything is cached by content: a second run recomputes nothing and takes seconds.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from sim2radar.cli._app import app, exit_unless_writable
from sim2radar.experiment.folder import SweepFolder
from sim2radar.factory.spec import MAX_FRAMES_PER_WORLD, MAX_WORLDS

__all__ = ["DEMO_SIZES", "DEMO_WORKERS", "demo", "demo_sizes", "run_demo"]

#: worlds at once in each of the demo's data stages (threads): on 2 cores two worlds overlap one
#: world's single-threaded work (NumPy, mesh decimation, the store) with the other's multi-threaded
#: rendering and tracing, 15-20 % faster than one with the same outputs bit for bit; three were no
#: faster and took more memory (BENCHMARKS.md, "The main job")
DEMO_WORKERS = 2

#: the data each demo profile makes unless told otherwise: the ``smoke`` profile (a toy
#: detector whose APs mean nothing) checks the whole chain in a few minutes on 2 cores with
#: small datasets and small renders; every other profile uses the ``demo`` sizes
DEMO_SIZES: dict[str, dict[str, int | None]] = {
    "demo": {"worlds": 6, "frames": 4, "reference_worlds": 20, "reference_frames": 6,
             "width": None, "height": None, "spp": None},
    "smoke": {"worlds": 3, "frames": 2, "reference_worlds": 3, "reference_frames": 3,
              "width": 160, "height": 120, "spp": 4},
}


def demo_sizes(profile: str, **given: int | None) -> dict[str, int | None]:
    """The sizes of a demo run: the profile's :data:`DEMO_SIZES` (``demo``'s for any other
    profile) with every value in ``given`` that is not None on top."""
    sizes = dict(DEMO_SIZES.get(profile, DEMO_SIZES["demo"]))
    sizes.update({k: v for k, v in given.items() if v is not None})
    return sizes


def _manifest_status(summary: dict[str, Any], name: str, role: str) -> dict[str, Any]:
    geo = next(iter(summary["geometry"].values()), {})
    return {"name": name, "role": role,
            "scenes_ok": summary["frame_counts"]["ok"],
            "scenes_skipped": summary["frame_counts"]["skipped"],
            "scenes_failed": summary["frame_counts"]["failed"],
            "frames": sum(g.get("frames", 0) for g in summary["geometry"].values()),
            "points_per_frame_mean": geo.get("points_per_frame"),
            "labels_per_frame_mean": geo.get("labels_per_frame"),
            "geometry": {g: {"points_per_frame": v.get("points_per_frame"),
                             "labels_per_frame": v.get("labels_per_frame")}
                         for g, v in summary["geometry"].items()}}


def _reference_dataset(store: str, dataset: str, export_dir: Path, png_dir: Path | None,
                       verbose: bool, **plan: Any) -> dict[str, Any]:
    """The reference radar's dataset of a plan (:class:`sim2radar.tasks.reference.ReferenceRequest`
    fields: ``first_seed``, ``worlds``, ``frames_per_world``, ``run``), exported to
    ``export_dir``."""
    from sim2radar.cli.generate import run_generate
    from sim2radar.tasks.reference import ReferenceRequest

    request = ReferenceRequest(store=store, dataset=dataset, export_dir=str(export_dir), **plan)
    return run_generate(request, png_dir=png_dir, verbose=verbose)


def run_demo(
    out: Path,
    *,
    worlds: int = 6,
    frames: int = 4,
    reference_worlds: int = 20,
    reference_frames: int = 6,
    profile: str = "demo",
    ablations: bool = False,
    ablation_material: str = "concrete",
    rig: dict | None = None,
    workers: int = DEMO_WORKERS,
    verbose: bool = False,
) -> dict[str, Any]:
    """The main job (see the module docstring); returns a summary with every output's path.
    ``workers``: worlds at once in each data stage (threads; the outputs do not depend on it)."""
    from sim2radar.cli.experiment import run_sweep
    from sim2radar.cli.generate import run_generate
    from sim2radar.evaluate.gap import write_gap_report
    from sim2radar.fileio import write_json
    from sim2radar.tasks.generate import GenerateRequest
    from sim2radar.tasks.runner import RunOptions

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    store, data = str(out / "store"), out / "openpcdet"
    sweep_dir = out / "sweeps" / "demo"
    typer.secho("1/5 simulated domain (ray tracer on reconstructed and ground-truth geometry)",
                bold=True)
    spec = {"frames_per_world": frames, "rig": rig or {}}
    run = RunOptions(workers=workers)
    sim = run_generate(GenerateRequest(spec={**spec, "geometry": "both"},
                                       seeds=list(range(worlds)), store=store, dataset="demo",
                                       export_dir=str(data), run=run),
                       png_dir=out / "bev", verbose=verbose)
    one_material = None
    if ablations:
        one_material = run_generate(GenerateRequest(
            spec={**spec, "material_override": ablation_material}, seeds=list(range(worlds)),
            store=store, dataset="demo-one-material", export_dir=str(data / "one_material"),
            run=run),
            verbose=verbose)
    typer.secho("2/5 proxy-real domain (reference radar on other worlds)", bold=True)
    real = _reference_dataset(store, "reference", data / "proxy_real", out / "bev", verbose,
                              worlds=reference_worlds, frames_per_world=reference_frames,
                              run=run)
    typer.secho("3/5 sim-real gap (reference radar on the simulated domain's own frames)",
                bold=True)
    paired = _reference_dataset(store, "reference-paired", data / "proxy_real_paired", None,
                                verbose, first_seed=0, worlds=worlds, frames_per_world=frames,
                                run=run)
    gap = write_gap_report(data / "reconstructed", data / "proxy_real_paired",
                           SweepFolder(sweep_dir).gap_dir)
    write_json(SweepFolder(sweep_dir).generation_json, {"datasets": [
        _manifest_status(sim, "demo", "sim"), _manifest_status(real, "reference", "real"),
        _manifest_status(paired, "reference-paired", "gap")]
        + ([_manifest_status(one_material, "demo-one-material", "sim-one-material")]
           if one_material else [])})
    typer.secho(f"4/5 experiment sweep ({profile} profile)", bold=True)
    summary = run_sweep(str(data / "reconstructed"), str(data / "proxy_real"), profile=profile,
                        name="demo", out=str(out / "sweeps"), store=store,
                        datasets={"sim-gt": str(data / "ground_truth"),
                                  "sim-one-material": str(data / "one_material")}
                        if ablations else None,
                        ablations=ablations, verbose=verbose)
    typer.secho("5/5 preview and summary", bold=True)
    from sim2radar.worlds import (
        RigConfig,
        generate_world,
        make_rig_config,
        render_frame,
        trajectory,
    )
    from sim2radar.worlds.preview import contact_sheet

    rig_cfg = make_rig_config(rig) if rig else RigConfig()
    world = generate_world(0)
    pose = trajectory(world, 1, seed=0)[0]
    preview = contact_sheet(world, render_frame(world, pose, rig_cfg),
                            out / "preview_world0.png", rig_cfg)
    result = {"generate": sim, "reference": real, "reference_paired": paired, "gap": gap,
              "sweep": {k: v for k, v in summary.items() if k != "stats"},
              "preview": str(preview), "dashboard": summary["dashboard"]}
    (out / "summary.json").write_text(json.dumps(result, indent=1, default=str))
    return {**result, "stats": summary["stats"], "sweep_summary": summary}


@app.command()
def demo(
    out: Path = typer.Option(Path("out"), "--out", "-o", help="Output folder."),
    worlds: int | None = typer.Option(None, "--worlds", "-n", min=1, max=MAX_WORLDS, help="Simulated-domain worlds (seeds 0..) [6; smoke 3]."),
    frames: int | None = typer.Option(None, "--frames", "-m", min=1, max=MAX_FRAMES_PER_WORLD, help="Frames per simulated world [4; smoke 2]."),
    reference_worlds: int | None = typer.Option(None, min=1, max=MAX_WORLDS, help="Proxy-real worlds (seeds from 100000) [20; smoke 3]."),
    reference_frames: int | None = typer.Option(None, min=1, max=MAX_FRAMES_PER_WORLD, help="Frames per proxy-real world [6; smoke 3]."),
    profile: str = typer.Option("demo", help="Experiment profile (demo, smoke, paper, YAML)."),
    ablations: bool = typer.Option(False, help="Also run the ablation conditions."),
    width: int | None = typer.Option(None, help="Camera width [px] [640; smoke 160]."),
    height: int | None = typer.Option(None, help="Camera height [px] [480; smoke 120]."),
    spp: int | None = typer.Option(None, help="RGB samples per pixel [rig default; smoke 4]."),
    workers: int = typer.Option(DEMO_WORKERS, min=1, help="Worlds processed at once in each data stage (threads; the outputs do not depend on it)."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Show Prefect's logs."),
) -> None:
    """Run the whole mission on the built-in default: simulated and proxy-real radar datasets,
    the sim-real gap, the experiment sweep and its dashboard. No model weights needed."""
    from sim2radar.cli.experiment import print_sweep_summary
    from sim2radar.cli.generate import print_generate_summary
    from sim2radar.cli.simulate import _prefect_env

    exit_unless_writable(str(out))
    _prefect_env(verbose)
    size = demo_sizes(profile, worlds=worlds, frames=frames, reference_worlds=reference_worlds,
                      reference_frames=reference_frames, width=width, height=height, spp=spp)
    rig = {k: size[k] for k in ("width", "height", "spp") if size[k] is not None}
    typer.echo(f"{profile} profile: {size['worlds']} simulated worlds x {size['frames']} frames, "
               f"{size['reference_worlds']} proxy-real worlds x {size['reference_frames']} "
               f"frames" + (f", renders {rig.get('width', 640)}x{rig.get('height', 480)} px"
                            if rig else "") + " (options override)")
    try:
        res = run_demo(out, worlds=size["worlds"], frames=size["frames"],
                       reference_worlds=size["reference_worlds"],
                       reference_frames=size["reference_frames"], profile=profile,
                       ablations=ablations, rig=rig, workers=workers, verbose=verbose)
    except (ValueError, FileNotFoundError) as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    print_generate_summary(res["generate"])
    print_sweep_summary(res["sweep_summary"])
    typer.echo(f"gap report: {Path(res['sweep']['sweep_dir']) / 'gap'}")
    typer.echo(f"preview:    {res['preview']}")
    typer.secho(f"dashboard:  {res['dashboard']}", bold=True)
    failed = (res["generate"]["counts"]["failed"] + res["reference"]["counts"]["failed"]
              + res["sweep"]["counts"]["failed"])
    if failed:
        raise typer.Exit(1)
