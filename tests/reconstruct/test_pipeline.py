"""The four-stage pipeline end to end, configs, bad input, exporters and the radar hand-off."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.evaluate.reconstruction import score_reconstruction
from sim2radar.mesh import load_scene
from sim2radar.reconstruct import (
    MATERIAL_BACKENDS,
    FrameInput,
    MaterialLabel,
    ReconstructionConfig,
    ReconstructionInputError,
    build_backends,
    reconstruct,
)
from sim2radar.reconstruct.synthetic import corridor_frame
from sim2radar.registry import UnknownBackendError


@pytest.fixture(scope="module")
def frame():
    return corridor_frame(160, 120, seed=1)


def _inp(f, **kw):
    return FrameInput(f.rgb, f.intrinsics, f.lidar_points, name="corridor", **kw)


@pytest.fixture(scope="module")
def builtin_scene(frame):
    return reconstruct(_inp(frame), ReconstructionConfig.preset("builtin-oracle-depth"),
                       ground_truth=frame)


def test_oracle_pipeline_reproduces_the_ground_truth(frame):
    scene = reconstruct(_inp(frame), ReconstructionConfig.preset("oracle"), ground_truth=frame)
    s = score_reconstruction(scene, frame)
    assert s.depth["abs_rel"] == 0 and s.segmentation.miou() == 1
    assert s.materials.accuracy() == 1
    assert {"depth", "segments", "materials", "meshing", "doors", "total"} <= set(scene.timings_s)


def test_builtin_stages_on_exact_depth(frame, builtin_scene):
    s = score_reconstruction(builtin_scene, frame).summary()
    assert s["miou"] > 0.5
    assert s["material_acc"] > 0.8
    # the nearest door (large in the image) gets a box within IoU 0.3 of the truth
    assert s["door_recall@0.3"] >= 0.25
    assert all(m.material != "unknown" for m in builtin_scene.meshes)


def test_scene_goes_to_the_radar_frame_and_simulator(frame, builtin_scene):
    radar_from_camera = np.linalg.inv(frame.radar_to_world) @ frame.camera_to_world
    meshes = builtin_scene.meshes_in(radar_from_camera)
    floor = [m for m in meshes if m.semantic == "floor"]
    assert floor
    # the radar is 1.4 m above the floor in the synthetic rig
    assert np.median(floor[0].vertices[:, 2]) == pytest.approx(-1.4, abs=0.05)
    boxes = builtin_scene.door_boxes_in(radar_from_camera)
    assert boxes.shape[1] == 7 and np.all(boxes[:, 2] > -1.4) and np.all(boxes[:, 0] > 0)
    from sim2radar.radar import load_radar_config, simulate_frame

    # the rig walking forward at 1 m/s (radar frame: x forward), as the factory's rig does
    points = simulate_frame(meshes, load_radar_config("ti-mmwcas"),
                            velocity_mps=np.array([1.0, 0.0, 0.0])).points
    assert len(points) > 20
    # detections lie on the reconstructed corridor: inside its walls, beyond the radar
    assert np.all(points[:, 0] > 0) and np.all(np.abs(points[:, 1]) < 3.0)


def test_level_frame_default_and_point_export(builtin_scene):
    pts = builtin_scene.points_in()
    assert pts.ndim == 2 and pts.shape[1] == 3 and np.isfinite(pts).all()
    # level frame: floor about 1.5 m below the camera
    floor = builtin_scene.semantic_id.ravel()[np.isfinite(builtin_scene.points_cam).all(-1).ravel()] == 2
    assert np.median(pts[floor, 2]) == pytest.approx(-1.5, abs=0.05)
    assert builtin_scene.floor_z_m == pytest.approx(-1.5, abs=0.05)


def test_write_scene_is_loadable_and_mitsuba_xml(tmp_path, builtin_scene):
    path = builtin_scene.write_scene(tmp_path / "scene")
    meshes = load_scene(path)
    assert len(meshes) == len(builtin_scene.meshes)
    assert {m.material for m in meshes} == {m.material for m in builtin_scene.meshes}
    xml = (tmp_path / "scene" / "scene.xml").read_text()
    assert xml.count("<shape") == len(meshes)


def test_artifacts_round_trip_through_the_store(tmp_path, builtin_scene, frame):
    from sim2radar.storage import ArtifactStore, meshes_from_table
    from sim2radar.storage.reconstruction import (
        frame_digest,
        read_reconstruction,
        write_scene_artifacts,
    )

    store = ArtifactStore(tmp_path / "store")
    cfg = ReconstructionConfig.preset("builtin-oracle-depth").to_dict()
    inputs = {"image": frame_digest(frame.rgb, frame.lidar_points)}
    keys = write_scene_artifacts(store, builtin_scene, inputs=inputs, config=cfg)
    again = write_scene_artifacts(store, builtin_scene, inputs=inputs, config=cfg)
    assert keys == again
    back = read_reconstruction(store, keys["reconstruction"])
    np.testing.assert_array_equal(back["semantic_id"], builtin_scene.semantic_id)
    np.testing.assert_allclose(back["door_boxes"], builtin_scene.door_boxes, atol=1e-6)
    assert back["segment_labels"] == list(builtin_scene.segment_labels)
    meshes = meshes_from_table(store.read("scene_meshes", keys["scene_meshes"]))
    assert len(meshes) == len(builtin_scene.meshes)


def test_config_yaml_presets_and_unknown_backend(tmp_path):
    (tmp_path / "m.onnx").write_bytes(b"")
    cfg_path = tmp_path / "c.yaml"
    cfg_path.write_text("depth: {name: moge, options: {model_path: m.onnx}}\n"
                        "segments: builtin\nmaterials: {name: prior}\nmeshing: {stride_px: 3}\n")
    cfg = ReconstructionConfig.from_yaml(cfg_path)
    assert cfg.depth.options["model_path"] == str((tmp_path / "m.onnx").resolve())
    assert cfg.segments.name == "builtin" and cfg.meshing.stride_px == 3
    (tmp_path / "bad.yaml").write_text("meshing: {strid_px: 3}\n")
    with pytest.raises(ValueError, match="bad.yaml"):
        ReconstructionConfig.from_yaml(tmp_path / "bad.yaml")
    with pytest.raises(UnknownBackendError, match="known backends"):
        build_backends(ReconstructionConfig(depth={"name": "midas"}))
    with pytest.raises(ValueError, match="unknown_material"):
        ReconstructionConfig(unknown_material="unknown")
    with pytest.raises(ValueError, match="preset"):
        ReconstructionConfig.preset("fancy")


def test_bad_inputs_give_clear_errors(frame):
    k = frame.intrinsics
    with pytest.raises(ReconstructionInputError, match="uint8"):
        FrameInput(frame.rgb.astype(np.float32) / 255, k)
    with pytest.raises(ReconstructionInputError, match="intrinsics"):
        FrameInput(frame.rgb, CameraIntrinsics.from_fov(100, 75, 60))
    with pytest.raises(ReconstructionInputError, match="NaN"):
        FrameInput(frame.rgb, k, np.full((5, 3), np.nan))
    with pytest.raises(ValueError):
        CameraIntrinsics(float("nan"), 1, 1, 1, 10, 10)
    with pytest.raises(ReconstructionInputError, match="ground truth"):
        reconstruct(_inp(frame), ReconstructionConfig.preset("oracle"))
    with pytest.raises(ReconstructionInputError, match="no valid pixel"):
        reconstruct(_inp(frame), ReconstructionConfig.preset("builtin-oracle-depth"),
                    ground_truth={"depth_m": np.zeros_like(frame.depth_m)})
    behind = -np.abs(frame.lidar_points)  # every LiDAR point behind the camera
    with pytest.raises(ReconstructionInputError):
        reconstruct(FrameInput(frame.rgb, k, behind), ReconstructionConfig())


def test_out_of_vocabulary_and_unknown_materials_are_recorded(frame):
    @MATERIAL_BACKENDS.register("test-garbage")
    class Garbage:
        def label(self, frame, depth, segments):
            return [MaterialLabel("steel" if i == 0 else "unknown", 0.5, "")
                    for i in range(segments.n_segments)]

    cfg = ReconstructionConfig(depth={"name": "oracle"}, materials={"name": "test-garbage"})
    scene = reconstruct(_inp(frame), cfg, ground_truth=frame)
    assert scene.segment_materials[0].material == "unknown"
    assert any("not in vocabulary" in f for f in scene.info["fallbacks"])
    assert any("plasterboard" in f for f in scene.info["fallbacks"])
    segment_meshes = [m for m in scene.meshes if not m.name.startswith("door_template")]
    assert {m.material for m in segment_meshes} == {"plasterboard"}
    assert (scene.material_id[scene.segment_id >= 0] == 0).all()


def test_cli_reconstructs_an_image_with_lidar(tmp_path, frame):
    import cv2
    import yaml
    from typer.testing import CliRunner

    from sim2radar.cli import app

    cv2.imwrite(str(tmp_path / "corridor.png"), frame.rgb[..., ::-1])
    (tmp_path / "K.yaml").write_text(yaml.safe_dump(frame.intrinsics.to_dict()))
    lidar = frame.lidar_points.copy()
    lidar[0] = np.nan  # a bad row is dropped and reported
    np.save(tmp_path / "lidar.npy", lidar)
    runner = CliRunner()
    args = ["reconstruct", str(tmp_path / "corridor.png"), "--intrinsics", str(tmp_path / "K.yaml"),
            "--lidar", str(tmp_path / "lidar.npy"), "--out", str(tmp_path / "out" / "store")]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "dropped 1 LiDAR rows" in result.output
    assert (tmp_path / "out" / "sheets" / "corridor.png").stat().st_size > 10_000
    assert load_scene(tmp_path / "out" / "scenes" / "corridor" / "scene.yaml")
    bad = runner.invoke(app, args[:3] + [str(tmp_path / "missing.yaml")] + args[4:])
    assert bad.exit_code != 0 and "missing.yaml" in bad.output
    # the rig calibration in the intrinsics file goes with every frame
    rig = {**frame.intrinsics.to_dict(), "camera_height_m": 1.5, "camera_pitch_deg": 0.0}
    (tmp_path / "K_rig.yaml").write_text(yaml.safe_dump(rig))
    with_rig = runner.invoke(app, args[:3] + [str(tmp_path / "K_rig.yaml")] + args[4:])
    assert with_rig.exit_code == 0, with_rig.output
    (tmp_path / "K_bad.yaml").write_text(yaml.safe_dump({**rig, "up_cam": [0, -1, 0]}))
    both = runner.invoke(app, args[:3] + [str(tmp_path / "K_bad.yaml")] + args[4:])
    assert both.exit_code != 0 and "not both" in both.output


def test_rig_calibration_fields_of_the_intrinsics_file(tmp_path):
    import yaml

    from sim2radar.reconstruct import up_from_pitch_roll
    from sim2radar.reconstruct.inputs import load_rig_calibration

    path = tmp_path / "K.yaml"
    base = {"fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}
    path.write_text(yaml.safe_dump(base))
    assert load_rig_calibration(path) == {}
    path.write_text(yaml.safe_dump({**base, "camera_pitch_deg": 3.0, "camera_height_m": 1.25}))
    rig = load_rig_calibration(path)
    np.testing.assert_allclose(rig["up_cam"], up_from_pitch_roll(3.0))
    assert rig["camera_height_m"] == 1.25
    path.write_text(yaml.safe_dump({**base, "up_cam": [0.0, -1.0]}))
    with pytest.raises(ValueError, match="K.yaml.*up_cam"):
        load_rig_calibration(path)


def test_shipped_configs_parse():
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "configs" / "reconstruct"
    names = {p.stem: ReconstructionConfig.from_yaml(p) for p in root.glob("*.yaml")}
    assert {"builtin", "oracle", "production"} <= set(names)
    assert names["builtin"].segments.name == "builtin"
    build_backends(names["builtin"])  # all options accepted by the backends
    assert Path(names["production"].depth.options["model_path"]).is_absolute()


def _write_job(tmp_path, frame, name="f0"):
    import cv2
    import yaml

    from sim2radar.tasks.reconstruct import ImageJob

    cv2.imwrite(str(tmp_path / f"{name}.png"), frame.rgb[..., ::-1])
    (tmp_path / "K.yaml").write_text(yaml.safe_dump(frame.intrinsics.to_dict()))
    np.save(tmp_path / f"{name}.npy", frame.lidar_points)
    return ImageJob(str(tmp_path / f"{name}.png"), str(tmp_path / "K.yaml"),
                    str(tmp_path / f"{name}.npy"))


def test_task_function_caches_by_content_key(tmp_path, frame):
    from sim2radar.tasks.common import record
    from sim2radar.tasks.reconstruct import reconstruct_image

    job = _write_job(tmp_path, frame)
    store = tmp_path / "store"
    first = reconstruct_image(job, store)
    assert first.status == "ok" and set(first.artifacts) == {"scene_meshes", "reconstruction"}
    again = reconstruct_image(job, store)
    assert again.status == "skipped" and again.artifacts == first.artifacts
    other = reconstruct_image(job, store, {"meshing": {"stride_px": 3}})
    assert other.status == "ok" and other.artifacts != first.artifacts
    (row,) = record(store, "demo", first)
    assert row["status"] == "ok" and row["artifacts"] == first.artifacts


@pytest.mark.slow
def test_flow_records_ok_skipped_and_failed(tmp_path, frame, monkeypatch):
    monkeypatch.setenv("PREFECT_HOME", str(tmp_path / "prefect"))
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.reconstruct import reconstruct_frames
    from sim2radar.tasks.reconstruct import ImageJob, ReconstructRequest

    job = _write_job(tmp_path, frame)
    (tmp_path / "broken.png").write_bytes(b"not an image")
    broken = ImageJob(str(tmp_path / "broken.png"), job.intrinsics, job.lidar)
    request = ReconstructRequest(jobs=[job, broken], store=str(tmp_path / "store"),
                                 dataset="d")
    s1 = run_flow(reconstruct_frames, request=request)   # Failed in Prefect, summary here
    assert s1["counts"] == {"ok": 1, "skipped": 0, "failed": 1}
    assert "broken.png" in s1["outcomes"][1]["error"]
    s2 = run_flow(reconstruct_frames, request=request)
    assert s2["counts"] == {"ok": 0, "skipped": 1, "failed": 1}


def test_mitsuba_dict_is_ray_traceable(builtin_scene, frame):
    import mitsuba as mi

    scene = mi.load_dict(builtin_scene.to_mitsuba_dict())
    # a ray down the corridor from the level origin hits the reconstructed floor 1.5 m below
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(0.5, 0, 0), mi.Vector3f(3.0, 0, -1)))
    hit = np.array(si.p).ravel()
    assert hit[2] == pytest.approx(-1.5, abs=0.05)


def test_up_from_pitch_roll_matches_a_rotated_camera():
    """The up of a camera pitched down by p and rolled by r is world +z seen in its frame."""
    from sim2radar.reconstruct import up_from_pitch_roll

    p, r = np.radians(7.0), np.radians(-4.0)
    # level camera (OpenCV) in a z-up world looking along +x: x_cam = -y, y_cam = -z, z_cam = +x
    cam = np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])  # columns: camera axes in the world
    pitch = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    roll = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])
    cam_to_world = pitch @ cam @ roll  # pitch about the world's y, roll about the optical axis
    want = cam_to_world.T @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(up_from_pitch_roll(7.0, -4.0), want, atol=1e-12)
    np.testing.assert_allclose(up_from_pitch_roll(0.0), [0.0, -1.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="pitch_deg"):
        up_from_pitch_roll(95.0)


def test_rig_calibration_is_validated_used_and_switchable(frame):
    """A frame's rig calibration is checked, reaches the depth stage (its up and floor), is
    recorded in the scene, changes the frame digest, and ``rig_calibration: false`` drops it."""
    from sim2radar.storage.reconstruction import frame_digest

    k = frame.intrinsics
    with pytest.raises(ReconstructionInputError, match="up_cam"):
        FrameInput(frame.rgb, k, up_cam=[0.0, 0.0, 0.0])
    with pytest.raises(ReconstructionInputError, match="camera_height_m"):
        FrameInput(frame.rgb, k, camera_height_m=-1.0)
    rig = frame.rig_calibration
    assert rig["camera_height_m"] == pytest.approx(1.5)
    inp = _inp(frame, **rig)
    assert inp.up_cam == pytest.approx(rig["up_cam"]) and inp.rig_calibration
    scene = reconstruct(inp, ReconstructionConfig())
    assert scene.info["rig_calibration"] == inp.rig_calibration
    assert scene.info["depth"]["up_cam"] == pytest.approx(list(rig["up_cam"]))
    assert scene.info["up_cam"] == pytest.approx(list(rig["up_cam"]), abs=0.02)
    off = reconstruct(inp, ReconstructionConfig(rig_calibration=False))
    assert off.info["rig_calibration"] == {}
    assert frame_digest(frame.rgb, frame.lidar_points, inp.rig_calibration) != \
        frame_digest(frame.rgb, frame.lidar_points)
    assert frame_digest(frame.rgb, frame.lidar_points, {}) == \
        frame_digest(frame.rgb, frame.lidar_points)
