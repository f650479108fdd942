"""The storage-I/O tasks (manifest writes) retry only what can flake: a permission error on
the store fails at once (it was retried 3 times over 21 s), a dropped connection is retried."""

from __future__ import annotations

import errno

import pytest

from sim2radar.flows.engine import record_task
from sim2radar.storage.manifest import Manifest
from sim2radar.tasks.common import REMOTE_IO_RETRIES, Outcome

#: the one manifest task every flow uses, with outcomes of each kind to record: a scene, a
#: reconstructed image, a world render, a dataset world with a frame (generate, captures)
RECORD_TASKS = [
    (record_task, Outcome("s", "ok", source="s.yaml", measured={"n_points": [3, 4]})),
    (record_task, Outcome("f", "ok", source="f.png")),
    (record_task, Outcome("world_000001", "ok", seed=1)),
    (record_task, Outcome("world_000002", "ok", seed=2,
                          parts=[Outcome("world_000002_f000", "ok", index=0)])),
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
        # two flakes, then it went through (and each frame's row after it)
        assert calls == [outcome.id] * 3 + [p.id for p in outcome.parts], (task.name, calls)
        assert task.retries == REMOTE_IO_RETRIES
