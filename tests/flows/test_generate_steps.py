"""The procedural path runs the same step tasks as the capture path: render, the
reconstruction's steps per frame, simulate per frame and geometry — visible per world in
Prefect, Cached when their artifact exists."""

from __future__ import annotations

from tests.flows.test_capture_dataset import _task_runs

RIG = {"width": 160, "height": 120, "spp": 4}


def test_world_steps_are_tasks_and_a_rerun_is_cached(prefect_server, tmp_path):
    from flows.generate_dataset import generate_dataset

    kw = dict(n_worlds=1, frames_per_world=1, store=tmp_path / "store", dataset="steps",
              geometry="both", rig=RIG, first_seed=3)
    first = generate_dataset(**kw)
    assert first["counts"]["ok"] == 1 and first["frame_counts"]["ok"] == 1
    states = _task_runs("generate-dataset")
    assert states["world-3"] == "Completed"
    for step in ("render", "depth-f000", "segments-f000", "materials-f000", "scene-f000",
                 "simulate-f000-ground_truth", "simulate-f000-reconstructed"):
        assert states[f"world_000003-{step}"] == "Completed", step

    again = generate_dataset(**kw)
    assert again["counts"]["skipped"] == 1
    states = _task_runs("generate-dataset")
    assert states["world_000003-render"] == "Cached"
    # the frame and its reconstruction are cached: no reconstruction or simulate step runs
    assert not any("depth" in n or "simulate" in n for n in states)
