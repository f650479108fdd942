"""World artifacts in the store: content keys, round trip, skip on rerun, manifest, flow."""

from __future__ import annotations

import numpy as np

from sim2radar.storage import ArtifactStore, meshes_from_table
from sim2radar.storage.worlds import decode_png, encode_png, frames_from_table
from sim2radar.tasks.runner import PlainRunner
from sim2radar.tasks.worlds import (
    WorldsRequest,
    generate_world_artifacts,
    generate_worlds,
    world_keys,
)
from sim2radar.worlds import generate_world, make_world_config
from tests.worlds._helpers import SMALL_RIG

SHORT = make_world_config({"corridor_length_m": [10, 12], "layout_probs": {"straight": 1.0}})


def test_png_round_trip():
    rgb = np.random.default_rng(0).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    assert np.array_equal(decode_png(encode_png(rgb)), rgb)
    ids = np.arange(35, dtype=np.uint16).reshape(5, 7) * 1000
    assert np.array_equal(decode_png(encode_png(ids)), ids)


def test_keys_change_with_config_and_seed():
    a = world_keys(1, 2, SHORT, SMALL_RIG)
    assert a == world_keys(1, 2, SHORT, SMALL_RIG)
    assert a["world_specs"] != world_keys(2, 2, SHORT, SMALL_RIG)["world_specs"]
    b = world_keys(1, 2, SHORT, SMALL_RIG.model_copy(update={"spp": 8}))
    assert b["world_specs"] == a["world_specs"] and b["world_frames"] != a["world_frames"]
    c = world_keys(1, 2, make_world_config({"corridor_length_m": [10, 13]}), SMALL_RIG)
    assert c["scene_meshes"] != a["scene_meshes"]


def test_world_artifacts_round_trip_and_skip(tmp_path):
    store = ArtifactStore(tmp_path / "store")
    out = generate_world_artifacts(5, 2, store, SHORT, SMALL_RIG)
    assert out.status == "ok" and out.measured["n_frames"] == 2
    for stage, key in out.artifacts.items():
        assert store.exists(stage, key), stage
    world = generate_world(5, SHORT)
    meshes = meshes_from_table(store.read("scene_meshes", out.artifacts["scene_meshes"]))
    assert [m.name for m in meshes] == [m.name for m in world.meshes]
    assert np.allclose(meshes[0].vertices, world.meshes[0].vertices)
    spec = store.read("world_specs", out.artifacts["world_specs"]).to_pylist()[0]
    assert spec["seed"] == 5 and spec["object_materials"] == [o.material for o in world.objects]
    assert np.allclose(spec["door_boxes_world"], world.door_boxes_world, atol=1e-5)

    frames = frames_from_table(store.read("world_frames", out.artifacts["world_frames"]))
    from sim2radar.worlds import render_frame, trajectory

    ref = render_frame(world, trajectory(world, 2, seed=0)[1], SMALL_RIG)
    got = frames[1]
    assert np.array_equal(got.rgb, ref.rgb)
    assert np.array_equal(got.instance_id, ref.instance_id)
    assert np.array_equal(got.semantic_id, ref.semantic_id)
    assert np.array_equal(got.material_id, ref.material_id)
    # float16 depth: relative error <= 2^-11
    assert np.allclose(got.depth_m, ref.depth_m, rtol=2**-10, atol=0)
    assert np.allclose(got.lidar_points, ref.lidar_points)
    assert np.allclose(got.radar_to_world, ref.radar_to_world)
    assert np.array_equal(got.door_visible, ref.door_visible)
    assert np.allclose(got.door_boxes_radar, ref.door_boxes_radar, atol=1e-5)
    dots = np.sum(got.normals * ref.normals, axis=-1)
    assert dots.min() > 0.999

    again = generate_world_artifacts(5, 2, store, SHORT, SMALL_RIG)
    assert again.status == "skipped" and again.measured["doors_visible"] == out.measured["doors_visible"]


def test_plain_run_records_manifest_and_failures(tmp_path, monkeypatch):
    store = tmp_path / "store"
    import sim2radar.tasks.worlds as tw

    real = tw.generate_world_artifacts

    def flaky(seed, *args, **kwargs):
        if seed == 8:
            raise RuntimeError("boom")
        return real(seed, *args, **kwargs)

    monkeypatch.setattr(tw, "generate_world_artifacts", flaky)
    summary = generate_worlds(WorldsRequest(seeds=[7, 8], n_frames=1, store=str(store),
                                            dataset="ds", world=SHORT, rig=SMALL_RIG),
                              PlainRunner())
    assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 1}
    rows = {r["scene_id"]: r for r in ArtifactStore(store).manifest("ds").rows()}
    assert rows["world_000007"]["status"] == "ok"
    assert rows["world_000008"]["status"] == "failed" and "boom" in rows["world_000008"]["error"]


def test_flow_generates_and_then_skips(tmp_path, prefect_server):
    from sim2radar.flows.worlds import generate_worlds_flow

    request = WorldsRequest(seeds=[3], n_frames=1, store=str(tmp_path / "store"),
                            dataset="flowds", world=SHORT, rig=SMALL_RIG)
    first = generate_worlds_flow(request)
    assert first["counts"] == {"ok": 1, "skipped": 0, "failed": 0}
    second = generate_worlds_flow(request)
    assert second["counts"] == {"ok": 0, "skipped": 1, "failed": 0}
    rows = ArtifactStore(tmp_path / "store").manifest("flowds").rows()
    assert [r["status"] for r in rows] == ["skipped"] and rows[0]["attempts"] == 2


def test_radar_point_clouds_per_frame(tmp_path):
    from sim2radar.storage import radar_frames_from_table

    store = ArtifactStore(tmp_path / "store")
    out = generate_world_artifacts(6, 2, store, SHORT, SMALL_RIG, radar="ti-mmwcas")
    assert out.status == "ok" and "radar_points" in out.artifacts
    radar = radar_frames_from_table(store.read("radar_points", out.artifacts["radar_points"]))
    frames = frames_from_table(store.read("world_frames", out.artifacts["world_frames"]))
    assert len(radar) == len(frames) == 2
    for r, f in zip(radar, frames, strict=True):
        assert len(r.points) > 20
        assert np.allclose(r.radar_to_world, f.radar_to_world)
        labelled = f.door_in_fov & f.door_in_range
        assert len(r.boxes) == labelled.sum() and set(r.box_labels) <= {"door"}
        assert np.allclose(r.boxes, f.door_boxes_radar[labelled], atol=1e-5)
    # without radar the keys of the other artifacts are unchanged -> cached
    again = generate_world_artifacts(6, 2, store, SHORT, SMALL_RIG)
    assert again.status == "skipped"
