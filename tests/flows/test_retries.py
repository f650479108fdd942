"""The storage-I/O tasks (manifest writes) retry only what can flake: a permission error on
the store fails at once (it was retried 3 times over 21 s), a dropped connection is retried."""

from __future__ import annotations

import errno

import pytest
from sim2radar.flows._steps import record_scene_task
from sim2radar.storage.manifest import Manifest
from sim2radar.tasks.common import REMOTE_IO_RETRIES
from sim2radar.tasks.dataset import WorldDatasetOutcome
from sim2radar.tasks.radar import SceneOutcome, record_outcome_task
from sim2radar.tasks.reconstruct import ReconOutcome, record_recon_outcome_task
from sim2radar.tasks.worlds import WorldOutcome, record_world_outcome_task

#: every task retried with REMOTE_IO_RETRIES that this file covers, with an outcome to record
RECORD_TASKS = [
    (record_outcome_task, SceneOutcome(scene_id="s", source="s.yaml", status="ok")),
    (record_recon_outcome_task, ReconOutcome("f", "f.png", "ok")),
    (record_world_outcome_task, WorldOutcome(world_id="world_000001", seed=1, status="ok")),
    (record_scene_task, WorldDatasetOutcome("world_000002", 2, "ok")),  # generate, captures
]


def test_manifest_tasks_retry_only_transient_io(prefect_server, tmp_path, monkeypatch):
    from prefect import flow

    calls: list[str] = []
    failures: list[BaseException] = []

    def upsert(self, scene_id, status, **kwargs):
        calls.append(scene_id)
        if failures:
            raise failures.pop(0)
        return {"scene_id": scene_id, "status": status}

    monkeypatch.setattr(Manifest, "upsert", upsert)

    @flow
    def record(task, outcome):
        return task.with_options(retry_delay_seconds=0)(str(tmp_path / "store"), "d", outcome)

    for task, outcome in RECORD_TASKS:
        calls.clear()
        failures[:] = [PermissionError(errno.EACCES, "Permission denied", "store/manifests")]
        with pytest.raises(PermissionError):
            record(task, outcome)
        assert len(calls) == 1, (task.name, calls)  # no retry: it would fail the same way
        calls.clear()
        failures[:] = [ConnectionError("reset by peer"), TimeoutError("slow")]
        record(task, outcome)
        assert len(calls) == 3, (task.name, calls)  # two flakes, then it went through
        assert task.retries == REMOTE_IO_RETRIES
