"""The capture factory end to end: a capture folder (rendered from procedural worlds, no ground
truth passed in) -> per-stage Prefect tasks -> radar dataset in OpenPCDet layout."""

from __future__ import annotations

import json
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from sim2radar.storage import ArtifactStore

FRAMES = 3


@pytest.fixture(scope="module")
def capture_folder(tmp_path_factory):
    from sim2radar.factory.captures import write_capture_folder

    root = tmp_path_factory.mktemp("captures")
    write_capture_folder(root, [1, 2], rig={"width": 200, "height": 150, "spp": 4})
    broken = root / "scene_broken"
    broken.mkdir()
    (broken / "rgb.png").write_bytes(b"this is not a png")
    shutil.copy(root / "scene_001" / "intrinsics.yaml", broken / "intrinsics.yaml")
    no_lidar = root / "scene_nolidar"  # the default depth backend needs LiDAR
    no_lidar.mkdir()
    for name in ("rgb.png", "intrinsics.yaml"):
        shutil.copy(root / "scene_002" / name, no_lidar / name)
    return root


def _task_runs(flow_run_name_filter: str = "capture-dataset", wait_s: float = 60.0):
    """Task runs of the latest capture-dataset flow run: name -> state name.

    Prefect 3's server records task-run states from the events the task runs emit, after the
    fact: read right after the flow ends, a task run can still have no state (the full suite
    once read ``None``) or a non-final one. Read again until every state is final."""
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import FlowFilter, FlowRunFilter
    from prefect.client.schemas.sorting import FlowRunSort

    deadline = time.monotonic() + wait_s
    with get_client(sync_client=True) as client:
        run = client.read_flow_runs(flow_filter=FlowFilter(name={"any_": [flow_run_name_filter]}),
                                    sort=FlowRunSort.START_TIME_DESC, limit=1)[0]
        while True:
            runs = client.read_task_runs(flow_run_filter=FlowRunFilter(id={"any_": [run.id]}))
            if all(r.state is not None and r.state.is_final() for r in runs) or \
                    time.monotonic() > deadline:
                break
            time.sleep(0.5)
    return {r.name: (r.state.name if r.state is not None else None) for r in runs}


def test_capture_folder_to_radar_dataset_stage_by_stage(prefect_server, capture_folder, tmp_path):
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.capture_dataset import capture_dataset
    from sim2radar.tasks.capture import CAPTURE_DOMAIN, CaptureRequest
    from sim2radar.tasks.capture import capture_dataset as capture_plain
    from sim2radar.tasks.runner import PlainRunner

    store_root, export = tmp_path / "store", tmp_path / "openpcdet"
    request = CaptureRequest(captures=str(capture_folder), store=str(store_root), dataset="lab",
                             export_dir=str(export),
                             spec={"poses": {"frames": FRAMES}, "frames_per_task": 2})
    first = run_flow(capture_dataset, request=request)  # Failed in Prefect, summary here
    assert first["counts"] == {"ok": 2, "skipped": 0, "failed": 2}
    assert first["frame_counts"] == {"ok": 2 * FRAMES, "skipped": 0, "failed": 0}
    store = ArtifactStore(store_root)
    rows = {r["scene_id"]: r for r in store.manifest("lab").rows()}
    assert rows["scene_broken"]["status"] == "failed"
    assert "[inputs]" in rows["scene_broken"]["error"]
    assert "rgb.png: not a readable image" in rows["scene_broken"]["error"]
    assert rows["scene_nolidar"]["error"].startswith("[depth]")
    assert {f"scene_001_f{k:03d}" for k in range(FRAMES)} <= set(rows)
    for stage in ("depth_maps", "segmentations", "material_labels", "scene_meshes",
                  "reconstruction"):
        assert store.exists(stage, rows["scene_001"]["artifacts"][stage]), stage

    # every step of every scene is its own task run; simulate runs per batch of 2 poses
    states = _task_runs()
    for stage in ("depth", "segments", "materials", "scene", "poses"):
        assert states[f"scene_001-{stage}"] == "Completed", stage
    assert states["scene_001-simulate-f000"] == states["scene_001-simulate-f002"] == "Completed"
    assert "scene_broken-depth" not in states  # its inputs failed before any step
    assert states["scene_nolidar-depth"] == "Failed" and "scene_nolidar-segments" not in states

    # the OpenPCDet export: every frame's points and labels, the domain in dataset.json
    meta = json.loads((export / "dataset.json").read_text())
    assert meta["domain"] == CAPTURE_DOMAIN and meta["frames"] == 2 * FRAMES
    assert len(list((export / "points").glob("*.npy"))) == 2 * FRAMES
    pts = np.load(export / "points" / "scene_001_f000.npy")
    assert pts.ndim == 2 and pts.shape[1] == 4 and len(pts) > 10
    table = {r["scene"]: r for r in first["stage_table"]}
    assert table["scene_001"]["frames"] == FRAMES and table["scene_001"]["points_per_frame"] > 10
    assert table["scene_broken"]["status"] == "failed"

    # a second run computes nothing: every step ends Cached, the frames are read back
    second = run_flow(capture_dataset, request=request)
    assert second["counts"] == {"ok": 0, "skipped": 2, "failed": 2}
    states = _task_runs()
    for stage in ("depth", "segments", "materials", "scene"):
        assert states[f"scene_002-{stage}"] == "Cached", stage
    assert second["stage_table"][0]["total_s"] < first["stage_table"][0]["total_s"]

    # the plain loop runs the same per-scene function: the same artifact keys
    plain = capture_plain(request.model_copy(update={"store": str(tmp_path / "plain"),
                                                     "export_dir": None}), PlainRunner())
    keys = lambda s: sorted(f["artifacts"]["dataset_frames/reconstructed"]  # noqa: E731
                            for w in s["outcomes"] for f in w["parts"])
    assert keys(plain) == keys(first)


def test_staged_reconstruction_equals_the_one_call_pipeline(capture_folder, tmp_path):
    from sim2radar.factory.captures import CaptureSpec, find_captures, load_capture_frame
    from sim2radar.reconstruct import reconstruct
    from sim2radar.storage.reconstruction import read_reconstruction
    from sim2radar.tasks.capture import process_capture_scene

    scene = find_captures(capture_folder)[0]
    spec = CaptureSpec(radar="ti-mmwcas", reconstruction=None, poses={"frames": 1})
    out = process_capture_scene(scene, spec, str(tmp_path / "s"))
    staged = read_reconstruction(ArtifactStore(tmp_path / "s"), out.artifacts["reconstruction"])
    direct = reconstruct(load_capture_frame(scene)[0])
    np.testing.assert_array_equal(staged["door_boxes"], direct.door_boxes)
    np.testing.assert_array_equal(staged["segment_id"], direct.segment_id)
    assert staged["segment_materials"] == [m.material for m in direct.segment_materials]


def test_a_scenes_views_fill_the_radars_field_of_view(tmp_path):
    """A capture scene with views/ and poses.txt: its reconstruction is fused with its earlier
    view, so the radar's geometry reaches beyond the camera's ±33° and its frames hold points
    there; the frames' keys name the views (a scene without them keeps its keys); the view's
    reconstruction is cached like the scene's."""
    from sim2radar.factory.captures import (
        CaptureSpec,
        find_captures,
        scene_views,
        write_capture_folder,
    )
    from sim2radar.tasks.capture import process_capture_scene
    from sim2radar.tasks.dataset import read_dataset_frame

    write_capture_folder(tmp_path / "cap", [4], rig={"width": 200, "height": 150, "spp": 4},
                         views=1)
    (scene,) = find_captures(tmp_path / "cap")
    assert [v.split("/")[-1] for v in scene.views] == ["v1"] and scene.poses
    (view, scene_from_view), = scene_views(scene, 1)
    assert view.scene_id == "scene_004/v1" and view.intrinsics.endswith("v1/intrinsics.yaml")
    # the earlier view's camera sits behind the scene's (OpenCV z forward): negative z
    assert scene_from_view[2, 3] < -0.1

    def run(k):
        spec = CaptureSpec(radar="ti-mmwcas", reconstruction={"fusion": {"frames": k}},
                           poses={"frames": 2})
        out = process_capture_scene(scene, spec, str(tmp_path / "store"))
        assert out.status in ("ok", "skipped"), out.error
        keys = [f.artifacts["dataset_frames/reconstructed"] for f in out.parts]
        frames = [read_dataset_frame(tmp_path / "store", k) for k in keys]
        az = np.concatenate([np.degrees(np.arctan2(f.points[:, 1], f.points[:, 0]))
                             for f in frames])
        return out, keys, az

    alone, keys0, az0 = run(0)
    fused, keys1, az1 = run(1)
    assert "views/scene_004/v1" in fused.artifacts and "views/scene_004/v1" not in alone.artifacts
    assert set(keys0).isdisjoint(keys1)
    # the points' azimuth (1-99 %): the camera's ±33° alone (the sampled poses turn up to
    # ±20°), about ±55° with the earlier view (measured: +-30 -> +-55 deg, world 4, 2 m apart)
    lo0, hi0 = np.percentile(az0, [1, 99])
    lo1, hi1 = np.percentile(az1, [1, 99])
    assert hi1 - lo1 > hi0 - lo0 + 20.0, ((lo0, hi0), (lo1, hi1))
    assert np.sum(np.abs(az1) > 40.0) > np.sum(np.abs(az0) > 40.0) + 5
    again = process_capture_scene(scene, CaptureSpec(
        radar="ti-mmwcas", reconstruction={"fusion": {"frames": 1}}, poses={"frames": 2}),
        str(tmp_path / "store"))
    assert again.status == "skipped"               # scene, view and frames all cached


def test_views_without_poses_or_with_a_bad_pose_fail_the_scene_naming_the_file(tmp_path):
    from sim2radar.factory.captures import (
        CaptureSpec,
        find_captures,
        read_poses_txt,
        write_capture_folder,
    )
    from sim2radar.tasks.capture import process_capture_scene

    (folder,) = write_capture_folder(tmp_path / "cap", [4], rig={"width": 80, "height": 60,
                                                                 "spp": 1}, views=1)
    poses = folder / "poses.txt"
    good = poses.read_text()
    assert list(read_poses_txt(poses)) == [".", "v1"]
    spec = CaptureSpec(radar="ti-mmwcas", poses={"frames": 1})
    cases = {
        "": "views.*but no poses.txt",
        good.replace("\nv1 ", "\nv9 "): r"view\(s\) \['v9'\] have no folder",
        good.replace(". ", "v3 ", 1): "no pose for the scene's own view",
        good + "v1 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n": "given twice",
        good + "x 1 0 0\n": r"line \d+: 4 fields, expected 17",
        good.split("\nv1 ")[0] + "\nv1 2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n":
            r"line 3: the pose of view 'v1' is not a rigid transform",
        good.split("\nv1 ")[0] + "\nv1 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 one\n":
            "not a number",
    }
    for text, match in cases.items():
        if text:
            poses.write_text(text)
        else:
            poses.unlink()
        (scene,) = find_captures(tmp_path / "cap")
        out = process_capture_scene(scene, spec, str(tmp_path / "store"))
        assert out.status == "failed", text
        assert re.search(match, out.error), (match, out.error)
        assert "poses.txt" in out.error or "views" in out.error


def test_a_symlink_loop_fails_its_scene_alone_naming_the_file(tmp_path):
    """A capture folder where one scene's rgb.png links to itself: finding scenes does not
    abort, that scene fails naming the link, the other scene is unaffected."""
    from sim2radar.factory.captures import CaptureSpec, find_captures, write_capture_folder
    from sim2radar.tasks.capture import process_capture_scene

    write_capture_folder(tmp_path / "cap", [4, 5], rig={"width": 80, "height": 60, "spp": 1})
    scenes = find_captures(tmp_path / "cap")
    assert len(scenes) == 2
    rgb = Path(scenes[0].image)
    rgb.unlink()
    rgb.symlink_to(rgb.name)                       # rgb.png -> rgb.png
    scenes = find_captures(tmp_path / "cap")       # does not raise
    assert len(scenes) == 2
    out = process_capture_scene(scenes[0], CaptureSpec(radar="ti-mmwcas", poses={"frames": 1}),
                                str(tmp_path / "store"))
    assert out.status == "failed"
    assert "rgb.png" in out.error and "symlink" in out.error and "loop" in out.error
    assert Path(scenes[1].image).is_file()
