"""The procedural path runs the same step tasks as the capture path: render, the
reconstruction's steps per frame, simulate per frame and geometry — visible per world in
Prefect, Cached when their artifact exists."""

from __future__ import annotations

from tests.flows.test_capture_dataset import _task_runs

RIG = {"width": 160, "height": 120, "spp": 4}


def test_world_steps_are_tasks_and_a_rerun_is_cached(prefect_server, tmp_path):
    from sim2radar.flows.generate_dataset import GenerateRequest, generate_dataset

    request = GenerateRequest(spec={"frames_per_world": 1, "geometry": "both", "rig": RIG},
                              seeds=[3], store=str(tmp_path / "store"), dataset="steps")
    first = generate_dataset(request)
    assert first["counts"]["ok"] == 1 and first["frame_counts"]["ok"] == 1
    states = _task_runs("generate-dataset")
    assert states["world_000003"] == "Completed"
    for step in ("render", "depth-f000", "segments-f000", "materials-f000", "scene-f000",
                 "simulate-ground_truth", "simulate-reconstructed"):
        assert states[f"world_000003-{step}"] == "Completed", step

    again = generate_dataset(request)
    assert again["counts"]["skipped"] == 1
    states = _task_runs("generate-dataset")
    assert states["world_000003-render"] == "Cached"
    # the frame and its reconstruction are cached: no reconstruction or simulate step runs
    assert not any("depth" in n or "simulate" in n for n in states)


def test_a_run_publishes_a_world_table_and_a_finished_progress_artifact(prefect_server, tmp_path):
    import json

    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import ArtifactFilter

    from sim2radar.flows.generate_dataset import GenerateRequest, generate_dataset

    generate_dataset(GenerateRequest(
        spec={"frames_per_world": 1, "geometry": "ground_truth", "rig": RIG}, n_worlds=1,
        first_seed=4, store=str(tmp_path / "store"), dataset="table-run"))
    with get_client(sync_client=True) as client:
        arts = {a.key: a for a in client.read_artifacts(artifact_filter=ArtifactFilter(
            key={"any_": ["generate-table-run-worlds", "generate-table-run-progress"]}))}
    progress = arts["generate-table-run-progress"]
    assert float(progress.data) == 100.0
    table = arts["generate-table-run-worlds"].data
    rows = json.loads(table) if isinstance(table, str) else table
    assert rows[0]["world"] == "world_000004" and rows[0]["status"] == "ok"
    assert rows[0]["frames"] == 1 and rows[0]["simulate_ground_truth_s"] > 0
