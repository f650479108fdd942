"""DataLoader workers of a training run inside a process that ran a Prefect flow (a sweep's
runs do): the workers are forked from it and must not run Prefect's thread-exit hooks, which
made every worker exit with status 1 and torch fail the run (issue #31)."""

from __future__ import annotations

import multiprocessing

import pytest
from prefect import flow

from sim2radar.datasets import make_door_frames
from sim2radar.detect.augment import build_gt_database
from sim2radar.detect.batches import TrainingBatches
from tests.detect.conftest import small_config


@flow
def _tiny_flow(x: int) -> int:
    return x + 1


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                    reason="forked workers only")
def test_forked_workers_after_a_flow_run_finish_cleanly(prefect_server):
    assert _tiny_flow(1) == 2   # Prefect's services now hold thread-exit hooks here
    cfg = small_config(optimization=dict(batch_size=3, epochs=2))
    frames = make_door_frames(6, seed=1, points_per_frame=200)
    db = build_gt_database(frames, cfg.model.class_names, cfg.augmentation.min_points_in_gt)
    with TrainingBatches(frames, 3, cfg.augmentation, cfg.model, db, 0, "cpu", workers=2,
                         context="fork", epochs=2) as tb:
        got = [n for e in (0, 1) for *_, n in tb.epoch(e)]
        workers = list(tb._loader._iterator._workers)
    # leaving the block stopped the workers; torch raises if one exited with a non-zero status
    assert got == [3, 3, 3, 3]
    assert [w.exitcode for w in workers] == [0, 0]
