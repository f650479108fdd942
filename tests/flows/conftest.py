"""Flow/task test fixtures: tiny scene files (good and broken) and a Prefect test server.

The engine-backed tests share the session's temporary Prefect server (``prefect_server`` in
``tests/conftest.py``, ~10 s to start), so keep them few.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import sim2radar.radar as radar_mod
from sim2radar.scenes import pose_matrix
from tests.flows._scenes import PLATE_RANGE_M, RADAR_POSITION, RADAR_YAW_DEG, write_scene


@pytest.fixture
def plate_scene(tmp_path) -> Path:
    """A 1 m² metal plate 3 m in front of a radar standing at (1, 2, 1) looking along +y."""
    centre = (RADAR_POSITION[0], RADAR_POSITION[1] + PLATE_RANGE_M, RADAR_POSITION[2])
    return write_scene(
        tmp_path / "plate",
        "plate",
        [("plate", "metal", centre, (1.0, 0.02, 1.0))],
        poses=[
            {"position": list(RADAR_POSITION), "yaw_deg": RADAR_YAW_DEG},
            {"matrix": pose_matrix(RADAR_POSITION, RADAR_YAW_DEG).tolist()},
        ],
        boxes=[{"label": "door", "box": [*centre, 1.0, 0.02, 1.0, 0.0]}],
    )


@pytest.fixture
def broken_scenes(tmp_path) -> dict[str, Path]:
    """Scenes that must fail: a missing mesh file, an unknown material, a corrupt PLY."""
    missing = write_scene(tmp_path / "missing", "missing_mesh", [("wall", "concrete", (3, 0, 0), (0.1, 2, 2))])
    (missing.parent / "wall.ply").unlink()
    unknown = write_scene(tmp_path / "unknown", "unknown_material", [("wall", "unobtainium", (3, 0, 0), (0.1, 2, 2))])
    corrupt = write_scene(tmp_path / "corrupt", "corrupt_mesh", [("wall", "concrete", (3, 0, 0), (0.1, 2, 2))])
    (corrupt.parent / "wall.ply").write_bytes(b"this is not a ply file")
    return {"missing": missing, "unknown": unknown, "corrupt": corrupt}


@pytest.fixture
def count_sim(monkeypatch):
    """Count calls of the real simulate_frame."""
    calls = {"n": 0}
    real = radar_mod.simulate_frame

    def counting(*args, **kwargs):
        calls["n"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(radar_mod, "simulate_frame", counting)
    return calls
