"""sim2radar.tasks.radar through plain functions (no Prefect engine): store, skip, recompute, failures."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import yaml

from sim2radar.radar import load_radar_config
from sim2radar.storage import (
    ArtifactStore,
    canonical_json,
    meshes_from_table,
    radar_frames_from_table,
)
from sim2radar.tasks.radar import SimulateRequest, scene_keys, simulate_scene, simulate_scenes
from sim2radar.tasks.runner import PlainRunner
from tests.flows._scenes import PLATE_RANGE_M, write_scene


def test_plate_lands_3m_ahead_in_the_radar_frame_and_round_trips(plate_scene, tmp_path, count_sim):
    store = ArtifactStore(tmp_path / "store")
    out = simulate_scene(plate_scene, "ti-mmwcas", store, seed=0, png_dir=tmp_path / "png")
    assert out.status == "ok" and count_sim["n"] == 2  # two radar poses
    n_points = out.measured["n_points"]
    assert out.id == "plate" and len(n_points) == 2 and min(n_points) > 0
    frames = radar_frames_from_table(store.read("radar_points", out.artifacts["radar_points"]))
    radar = load_radar_config("ti-mmwcas")
    for f in frames:
        # the strongest return is the plate: straight ahead (radar frame) at 3 m ± one range bin
        best = f.points[np.argmax(f.points[:, 3])]
        assert np.hypot(best[0], best[1]) == pytest.approx(PLATE_RANGE_M, abs=radar.range_resolution_m + 0.02)
        assert abs(np.arctan2(best[1], best[0])) <= radar.azimuth_resolution_rad * 1.5
        # the ground-truth box came along, expressed in the radar frame (3 m ahead, heading -90°)
        np.testing.assert_allclose(f.boxes[0, :3], [PLATE_RANGE_M, 0.0, 0.0], atol=1e-5)
        assert abs(abs(f.boxes[0, 6]) - np.pi / 2) < 1e-5 and f.box_labels == ["door"]
    np.testing.assert_allclose(frames[0].radar_to_world, frames[1].radar_to_world, atol=1e-12)
    meshes = meshes_from_table(store.read("scene_meshes", out.artifacts["scene_meshes"]))
    assert [m.material for m in meshes] == ["metal"]
    pngs = out.measured["pngs"]
    assert len(pngs) == 2 and all(open(p, "rb").read(4) == b"\x89PNG" for p in pngs)
    prov = store.read_provenance("radar_points", out.artifacts["radar_points"])
    assert prov["config"]["radar"] == json.loads(canonical_json(radar.to_dict()))
    assert prov["seed"] == 0 and prov["inputs"] == {"scene": out.artifacts["scene_meshes"]}
    assert prov["timings_s"]["simulate"] > 0 and prov["versions"]["mitsuba"]


def test_second_run_computes_nothing(plate_scene, tmp_path, count_sim):
    store = ArtifactStore(tmp_path / "store")
    first = simulate_scene(plate_scene, "ti-mmwcas", store)
    path = store.path("radar_points", first.artifacts["radar_points"])
    mtime = os.stat(path).st_mtime_ns
    n_calls = count_sim["n"]
    second = simulate_scene(plate_scene, "ti-mmwcas", store)
    assert second.status == "skipped" and count_sim["n"] == n_calls
    assert second.artifacts == first.artifacts and second.measured["n_points"] == first.measured["n_points"]
    assert os.stat(path).st_mtime_ns == mtime
    assert simulate_scene(plate_scene, "ti-mmwcas", store, force=True).status == "ok"
    assert count_sim["n"] == n_calls + 2


def test_keys_change_with_config_seed_and_files_only(plate_scene, tmp_path):
    base = scene_keys(plate_scene, "ti-mmwcas", seed=0)
    assert scene_keys(plate_scene, "ti-mmwcas", seed=0) == base
    # a copy of the same files elsewhere is the same scene
    copy = tmp_path / "copy"
    copy.mkdir()
    for p in plate_scene.parent.iterdir():
        (copy / p.name).write_bytes(p.read_bytes())
    assert scene_keys(copy / plate_scene.name, "ti-mmwcas", seed=0) == base
    other_seed = scene_keys(plate_scene, "ti-mmwcas", seed=1)
    assert other_seed["scene_meshes"] == base["scene_meshes"]
    assert other_seed["radar_points"] != base["radar_points"]
    other_radar = scene_keys(plate_scene, load_radar_config("ti-mmwcas").with_updates(max_bounces=1))
    assert other_radar["radar_points"] != base["radar_points"]
    # editing a mesh file changes both keys
    ply = copy / "plate.ply"
    ply.write_bytes(ply.read_bytes()[:-4] + b"\x00\x00\x00\x00")
    edited = scene_keys(copy / plate_scene.name, "ti-mmwcas", seed=0)
    assert edited["scene_meshes"] != base["scene_meshes"] and edited["radar_points"] != base["radar_points"]


def _simulate(scenes, store):
    request = SimulateRequest(scenes=[str(s) for s in scenes], radar="ti-mmwcas",
                              store=store.root, dataset="t")
    return simulate_scenes(request, PlainRunner())


def test_broken_scenes_fail_clearly_and_the_others_finish(plate_scene, broken_scenes, tmp_path):
    store = ArtifactStore(tmp_path / "store")
    scenes = [broken_scenes["missing"], plate_scene, broken_scenes["unknown"], broken_scenes["corrupt"]]
    summary = _simulate(scenes, store)
    assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 3}
    rows = {r["scene_id"]: r for r in store.manifest("t").rows()}
    assert rows["plate"]["status"] == "ok" and rows["plate"]["artifacts"]["radar_points"]
    assert "wall.ply: mesh file not found" in rows["missing_mesh"]["error"]
    assert "MeshFileError" in rows["missing_mesh"]["error"]
    assert "unobtainium" in rows["unknown_material"]["error"]
    assert "known materials" in rows["unknown_material"]["error"]
    assert "not a PLY file" in rows["corrupt_mesh"]["error"]
    assert all(rows[s]["artifacts"] == {} for s in ("missing_mesh", "unknown_material", "corrupt_mesh"))
    # retry after fixing the scene: the failed one is computed, the good one skipped
    doc = yaml.safe_load(broken_scenes["unknown"].read_text())
    doc["meshes"][0]["material"] = "concrete"
    broken_scenes["unknown"].write_text(yaml.safe_dump(doc))
    again = _simulate([plate_scene, broken_scenes["unknown"]], store)
    assert again["counts"] == {"ok": 1, "skipped": 1, "failed": 0}
    rows = {r["scene_id"]: r for r in store.manifest("t").rows()}
    assert rows["unknown_material"]["status"] == "ok" and rows["unknown_material"]["attempts"] == 2
    assert rows["plate"]["status"] == "skipped"
    assert sorted(store.manifest("t").failed()) == ["corrupt_mesh", "missing_mesh"]


def test_scene_without_poses_uses_the_identity(tmp_path):
    path = write_scene(tmp_path, "bare", [("plate", "metal", (3.0, 0.0, 0.0), (0.02, 1.0, 1.0))])
    store = ArtifactStore(f"memory://bare-{os.getpid()}-{id(tmp_path)}")
    out = simulate_scene(path, "ti-mmwcas", store)
    (frame,) = radar_frames_from_table(store.read("radar_points", out.artifacts["radar_points"]))
    np.testing.assert_array_equal(frame.radar_to_world, np.eye(4))
    assert frame.boxes.shape == (0, 7) and len(frame.points) > 0
    assert out.measured["locations"]["radar_points"].startswith("memory://")
