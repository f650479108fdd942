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

from sim2radar.cli._app import app


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
) -> None:
    """Reconstruct material-labelled 3D scenes from RGB [+ LiDAR] and store them."""
    import numpy as np
    from rich.console import Console

    from sim2radar.camera import CameraIntrinsics
    from sim2radar.reconstruct import (
        FrameInput,
        ReconstructionConfig,
        ReconstructionInputError,
        build_backends,
        reconstruct,
    )
    from sim2radar.reconstruct.inputs import load_image, load_lidar, load_rig_calibration
    from sim2radar.reconstruct.sheet import stage_sheet
    from storage import ArtifactStore
    from storage.reconstruction import frame_digest, write_scene_artifacts

    console = Console()
    try:
        k = CameraIntrinsics.from_yaml(intrinsics)
    except (FileNotFoundError, ValueError) as exc:
        raise typer.BadParameter(str(exc), param_hint="--intrinsics") from None
    try:
        rig = load_rig_calibration(intrinsics)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--intrinsics") from None
    lidar = list(lidar or [])
    if lidar and len(lidar) != len(images):
        raise typer.BadParameter(
            f"got {len(lidar)} --lidar file(s) for {len(images)} image(s); give one per image",
            param_hint="--lidar",
        )
    cfg = ReconstructionConfig.from_yaml(config) if config else ReconstructionConfig.preset(preset)
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

    failures = 0
    for i, image in enumerate(images):
        name = image.stem
        try:
            rgb = load_image(image)
            pts, note = load_lidar(lidar[i]) if lidar else (None, "")
            if note:
                console.print(f"[yellow]{name}: {note}")
            frame = FrameInput(rgb, k, pts, name=name, **rig)
            scene = reconstruct(frame, cfg, backends=backends)
        except (ReconstructionInputError, ValueError) as exc:
            failures += 1
            console.print(f"[red]{name}: failed: {exc}")
            continue
        inputs = {"image": frame_digest(rgb, pts, frame.rig_calibration)}
        keys = write_scene_artifacts(store, scene, inputs=inputs, config=cfg.to_dict())
        scene_yaml = scene.write_scene(base / "scenes" / name)
        sheet = sheets / f"{name}.png"
        stage_sheet(scene, sheet, lidar_points=pts)
        labels = {lbl: scene.segment_labels.count(lbl) for lbl in sorted(set(scene.segment_labels))}
        console.print(
            f"[green]{name}[/]: {scene.n_segments} segments {labels}, {len(scene.meshes)} meshes, "
            f"{len(scene.door_boxes)} door box(es), {scene.timings_s['total']:.2f} s"
        )
        for f in scene.info["fallbacks"]:
            console.print(f"  fallback: {f}")
        console.print(f"  artifacts: reconstruction/{keys['reconstruction']}, "
                      f"scene_meshes/{keys['scene_meshes']} in {store.root}")
        console.print(f"  scene: {scene_yaml}   sheet: {sheet}")
        if radar_cfg is not None:
            from sim2radar.radar import simulate_frame

            points = simulate_frame(scene.meshes_in(None), radar_cfg).points
            np.save(base / "scenes" / name / "radar_points.npy", points)
            console.print(f"  radar ({radar}): {len(points)} points (radar at the camera, "
                          "level frame) -> radar_points.npy")
    if failures:
        raise typer.Exit(code=1)
