"""Storage test helpers: a small radar_points table and a unique memory:// root per test."""

from __future__ import annotations

import uuid

import numpy as np
import pytest

from sim2radar.storage import radar_frames_to_table


@pytest.fixture
def frames_table():
    rng = np.random.default_rng(1)
    pts = [rng.normal(size=(n, 4)).astype(np.float32) for n in (50, 3)]
    return radar_frames_to_table(
        scene_id="corridor", radar_to_world=[np.eye(4)] * 2, points=pts, sim_seconds=[0.1, 0.2]
    )


@pytest.fixture
def memory_root():
    root = f"memory://sim2radar-test-{uuid.uuid4().hex}"
    yield root
    import fsspec

    fs = fsspec.filesystem("memory")
    path = root.removeprefix("memory://")
    if fs.exists(path):
        fs.rm(path, recursive=True)
