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


def load_lidar(path: Path, *, drop_invalid: bool = True) -> tuple:
    """Read an (N, ≥3) ``.npy`` of LiDAR points in the camera frame; return (points, note).

    Rows with NaN/inf are dropped (and reported) when ``drop_invalid``; otherwise they raise.
    """
    import numpy as np

    if not path.is_file():
        raise typer.BadParameter(f"{path}: LiDAR file not found")
    try:
        pts = np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - any read error is a bad file
        raise typer.BadParameter(f"{path}: cannot read as .npy ({exc})") from None
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise typer.BadParameter(
            f"{path}: LiDAR must be an (N, 3) array of camera-frame points [m] (x right, y down, "
            f"z forward), got shape {pts.shape}"
        )
    pts = pts[:, :3].astype(np.float32)
    bad = ~np.isfinite(pts).all(axis=1)
    note = ""
    if bad.any():
        if not drop_invalid:
            raise typer.BadParameter(f"{path}: {int(bad.sum())} LiDAR rows contain NaN/inf")
        pts = pts[~bad]
        note = f"dropped {int(bad.sum())} LiDAR rows with NaN/inf"
    return pts, note


def load_rig_calibration(path: Path) -> dict:
    """The optional rig calibration in an intrinsics YAML: ``camera_height_m`` (the camera's
    height above the floor [m]) and the camera's up — ``up_cam: [x, y, z]`` (camera frame: x
    right, y down, z forward) or ``camera_pitch_deg`` (down is positive) with
    ``camera_roll_deg`` (default 0). Returns ``FrameInput`` keyword arguments (empty without
    any of them)."""
    import numpy as np

    from sim2radar.configio import read_yaml_mapping
    from sim2radar.reconstruct import up_from_pitch_roll

    doc = read_yaml_mapping(path, what="intrinsics file", error=typer.BadParameter)
    out: dict = {}
    if "up_cam" in doc and "camera_pitch_deg" in doc:
        raise typer.BadParameter(f"{path}: give the camera's up as up_cam or as "
                                 "camera_pitch_deg (+ camera_roll_deg), not both")
    try:
        if "up_cam" in doc:
            up = np.asarray(doc["up_cam"], np.float64)
            if up.shape != (3,):
                raise ValueError(f"up_cam must be [x, y, z], got {doc['up_cam']!r}")
            out["up_cam"] = up
        elif "camera_pitch_deg" in doc or "camera_roll_deg" in doc:
            out["up_cam"] = up_from_pitch_roll(float(doc.get("camera_pitch_deg", 0.0)),
                                               float(doc.get("camera_roll_deg", 0.0)))
        if "camera_height_m" in doc:
            out["camera_height_m"] = float(doc["camera_height_m"])
    except (TypeError, ValueError) as exc:
        raise typer.BadParameter(f"{path}: rig calibration: {exc}") from None
    return out


def load_image(path: Path):
    """Read an image file as (H, W, 3) uint8 RGB."""
    import cv2

    if not path.is_file():
        raise typer.BadParameter(f"{path}: image not found")
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise typer.BadParameter(f"{path}: not a readable image (PNG/JPEG/...)")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


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
    from sim2radar.reconstruct.sheet import stage_sheet
    from storage import ArtifactStore
    from storage.reconstruction import frame_digest, write_scene_artifacts

    console = Console()
    try:
        k = CameraIntrinsics.from_yaml(intrinsics)
    except (FileNotFoundError, ValueError) as exc:
        raise typer.BadParameter(str(exc), param_hint="--intrinsics") from None
    rig = load_rig_calibration(intrinsics)
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
        except (ReconstructionInputError, typer.BadParameter, ValueError) as exc:
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
