"""``sim2radar reconstruct`` command (RGB [+ LiDAR] -> material-labelled scene).

    sim2radar reconstruct IMAGE [IMAGE ...] --intrinsics K.yaml [--lidar L.npy] --out STORE
        [--config configs/reconstruct/production.yaml] [--sheet-dir DIR] [--radar ti-mmwcas]

For every image: the four stages (depth, segments + labels, materials, 3D), then the artifacts
(``scene_meshes`` + ``reconstruction``) in the Parquet store at ``STORE``, a scene folder
``STORE/../scenes/<name>/scene.yaml`` that ``sim2radar simulate`` accepts, and a PNG sheet of
the stages (paper Figure 2). Heavy imports happen inside the command.
"""

from __future__ import annotations

from pathlib import Path

import typer

from sim2radar.cli._app import app, exit_unless_writable
from sim2radar.cli._app import console as _console


@app.command("reconstruct")
def reconstruct_cmd(
    images: list[Path] = typer.Argument(..., help="RGB image(s) (PNG/JPEG)."),
    intrinsics: Path = typer.Option(..., "--intrinsics", "-k",
                                    help="YAML with fx, fy, cx, cy, width, height (or K); "
                                         "optionally the rig calibration camera_height_m and "
                                         "camera_pitch_deg / camera_roll_deg (or up_cam)."),
    lidar: list[Path] = typer.Option(None, "--lidar",
                                     help="(N, 3) .npy LiDAR points in the camera frame, "
                                          "metres; one per image, same order."),
    out: Path = typer.Option(Path("out/store"), "--out", help="Artifact store (folder or URI)."),
    config: Path = typer.Option(None, "--config", help="Reconstruction config YAML."),
    preset: str = typer.Option("builtin", "--preset",
                               help="builtin (LiDAR + built-in backends); use --config for "
                                    "moge / sam2-gdino / vlm."),
    sheet_dir: Path = typer.Option(None, "--sheet-dir",
                                   help="Where PNG sheets go (default: next to the store)."),
    radar: str = typer.Option(None, "--radar",
                              help="Also simulate radar points on the scene with this preset."),
    dataset: str = typer.Option("reconstruction", "--dataset", help="Manifest (dataset) name."),
    force: bool = typer.Option(False, help="Recompute frames even when cached."),
) -> None:
    """Reconstruct material-labelled 3D scenes from RGB [+ LiDAR] and store them.

    Every frame is a manifest row of --dataset: ok, skipped (cached by content key: a second
    run recomputes nothing) or failed with its error, while the others finish. Exit status: 0,
    1 when a frame failed, 2 for bad arguments (intrinsics, config, store).
    """
    import numpy as np

    from sim2radar.camera import CameraIntrinsics
    from sim2radar.reconstruct import ReconstructionConfig, build_backends
    from sim2radar.reconstruct.inputs import load_rig_calibration
    from sim2radar.storage import ArtifactStore, meshes_from_table
    from sim2radar.tasks.reconstruct import ImageJob, ReconstructRequest, reconstruct_images
    from sim2radar.tasks.runner import PlainRunner

    exit_unless_writable(str(out))
    console = _console()
    for option, check in (  # one intrinsics file for every image: a bad one is a bad argument
            ("--intrinsics", lambda: (CameraIntrinsics.from_yaml(intrinsics),
                                      load_rig_calibration(intrinsics))),
            ("--dataset", lambda: ArtifactStore(str(out)).manifest(dataset))):
        try:
            check()
        except (FileNotFoundError, ValueError) as exc:
            typer.secho(f"error: {option}: {exc}", fg="red", err=True)
            raise typer.Exit(2) from None
    lidar = list(lidar or [])
    if lidar and len(lidar) != len(images):
        raise typer.BadParameter(
            f"got {len(lidar)} --lidar file(s) for {len(images)} image(s); give one per image",
            param_hint="--lidar",
        )
    cfg = ReconstructionConfig.from_yaml(config) if config else ReconstructionConfig.preset(preset)
    from sim2radar.cli._datasets import preflight

    try:
        preflight(cfg)   # a misconfigured VLM server stops here, before any image
    except ValueError as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None
    if any(s.name == "oracle" for s in (cfg.depth, cfg.segments, cfg.materials)):
        raise typer.BadParameter("oracle backends need procedural-world ground truth; use the "
                                 "benchmark or the Python API for them", param_hint="--config")
    if cfg.depth.name == "lidar" and not lidar:
        raise typer.BadParameter("the 'lidar' depth backend needs --lidar (or choose a config "
                                 "with the 'moge' backend)", param_hint="--lidar")
    store = ArtifactStore(str(out))
    base = out.parent if "://" not in str(out) else Path("out")
    sheets = sheet_dir or base / "sheets"
    backends = build_backends(cfg)
    radar_cfg = None
    if radar:
        from sim2radar.radar import load_radar_config

        radar_cfg = load_radar_config(radar)

    def on_frame(outcome) -> None:
        name, keys = outcome.id, outcome.artifacts
        if outcome.status == "failed":
            console.print(f"[red]{name}: failed: {outcome.error}", soft_wrap=True)
            return
        if outcome.status == "skipped":
            console.print(f"[green]{name}[/]: skipped (cached)")
        else:
            info = outcome.measured["summary"]
            console.print(
                f"[green]{name}[/]: {sum(info['segments'].values())} segments "
                f"{info['segments']}, {info['meshes']} meshes, {info['door_boxes']} door "
                f"box(es), {outcome.timings_s['total']:.2f} s")
            for f in info["fallbacks"]:
                console.print(f"  fallback: {f}")
        console.print(f"  artifacts: reconstruction/{keys['reconstruction']}, "
                      f"scene_meshes/{keys['scene_meshes']} in {store.root}")
        console.print(f"  scene: {base / 'scenes' / name / 'scene.yaml'}   "
                      f"sheet: {sheets / f'{name}.png'}")
        if radar_cfg is not None:  # on the stored level-frame meshes: cached frames too
            from sim2radar.radar import simulate_frame

            meshes = meshes_from_table(store.read("scene_meshes", keys["scene_meshes"]))
            points = simulate_frame(meshes, radar_cfg).points
            (base / "scenes" / name).mkdir(parents=True, exist_ok=True)
            np.save(base / "scenes" / name / "radar_points.npy", points)
            console.print(f"  radar ({radar}): {len(points)} points (radar at the camera, "
                          "level frame) -> radar_points.npy")

    jobs = [ImageJob(str(image), str(intrinsics), str(lidar[i]) if lidar else None)
            for i, image in enumerate(images)]
    request = ReconstructRequest(jobs=jobs, store=str(out), dataset=dataset, config=cfg,
                                 out_dir=str(base), sheet_dir=str(sheets), force=force)
    summary = reconstruct_images(request, PlainRunner(on_frame), backends=backends)
    c = summary["counts"]
    console.print(f"[bold]{c['ok']} computed, {c['skipped']} cached (skipped), "
                  f"{c['failed']} failed[/bold] — manifest: {summary['manifest']}")
    if c["failed"]:
        raise typer.Exit(code=1)
