"""The Prefect flow itself (ephemeral test API): resume without recompute, failures recorded."""

from __future__ import annotations

import pytest

from sim2radar.storage import ArtifactStore


def test_flow_runs_twice_second_computes_nothing_and_failures_are_recorded(
    prefect_server, plate_scene, broken_scenes, tmp_path, count_sim
):
    from sim2radar.flows import _progress
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.simulate import SceneFailures, SimulateRequest, simulate_dataset

    root = tmp_path / "store"
    scenes = [str(plate_scene), str(broken_scenes["unknown"])]
    request = SimulateRequest(scenes=scenes, radar="ti-mmwcas", store=str(root), dataset="t",
                              png_dir=str(tmp_path / "png"))
    seen = []
    with _progress.listen("simulate", lambda o: seen.append((o.id, o.status))):
        first = run_flow(simulate_dataset, request=request)  # Failed in Prefect, summary here
    assert first["counts"] == {"ok": 1, "skipped": 0, "failed": 1}
    assert sorted(seen) == [("plate", "ok"), ("unknown_material", "failed")]
    assert count_sim["n"] == 2  # two poses of the plate scene
    store = ArtifactStore(root)
    rows = {r["scene_id"]: r for r in store.manifest("t").rows()}
    assert rows["plate"]["status"] == "ok"
    assert "unobtainium" in rows["unknown_material"]["error"]
    assert len(list((tmp_path / "png").glob("plate_f*.png"))) == 2
    key = rows["plate"]["artifacts"]["radar_points"]
    assert store.exists("radar_points", key)

    # second run, same inputs: nothing simulated, the scene is recorded as skipped;
    # strict=True makes the flow fail at the end because one scene still fails
    with pytest.raises(SceneFailures, match="unknown_material"):
        run_flow(simulate_dataset, request=request.model_copy(update={"strict": True}))
    assert count_sim["n"] == 2
    rows = {r["scene_id"]: r for r in store.manifest("t").rows()}
    assert rows["plate"]["status"] == "skipped" and rows["plate"]["attempts"] == 2
    assert rows["plate"]["artifacts"]["radar_points"] == key
    assert rows["unknown_material"]["status"] == "failed" and rows["unknown_material"]["attempts"] == 2
