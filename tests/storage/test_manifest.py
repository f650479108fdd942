"""Manifests: one row per scene; upsert replaces; resume/retry semantics; concurrent writers."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

from sim2radar.storage import ArtifactStore


@pytest.fixture(params=["local", "memory"])
def manifest(request, tmp_path, memory_root):
    root = tmp_path / "store" if request.param == "local" else memory_root
    return ArtifactStore(root).manifest("demo")


def test_upsert_replaces_the_row_and_counts_attempts(manifest):
    assert manifest.rows() == [] and manifest.counts() == {"ok": 0, "skipped": 0, "failed": 0}
    manifest.upsert("corridor/a", "failed", error="MeshFileError: door.ply: mesh file not found")
    manifest.upsert("room", "ok", artifacts={"radar_points": "ab" * 10}, timings_s={"sim": 0.3})
    assert manifest.failed() == ["corridor/a"]
    # retry: the failed scene now succeeds; the row is replaced, not duplicated
    manifest.upsert("corridor/a", "ok", artifacts={"radar_points": "cd" * 10})
    rows = {r["scene_id"]: r for r in manifest.rows()}
    assert set(rows) == {"corridor/a", "room"}
    assert rows["corridor/a"]["status"] == "ok" and rows["corridor/a"]["error"] == ""
    assert rows["corridor/a"]["attempts"] == 2 and rows["room"]["attempts"] == 1
    assert rows["room"]["timings_s"] == {"sim": 0.3}
    assert manifest.get("room")["artifacts"] == {"radar_points": "ab" * 10}
    # resume: a second run finds the artifacts and records "skipped"
    manifest.upsert("room", "skipped", artifacts={"radar_points": "ab" * 10})
    assert manifest.counts() == {"ok": 1, "skipped": 1, "failed": 0}
    assert manifest.failed() == []


def test_bad_status_is_refused(manifest):
    with pytest.raises(ValueError, match="ok', 'skipped', 'failed"):
        manifest.upsert("x", "done")
    with pytest.raises(ValueError, match="dataset name"):
        manifest.store.manifest("../evil")


def test_concurrent_upserts_lose_no_row(manifest):
    ids = [f"scene_{i:02d}" for i in range(16)]
    with ThreadPoolExecutor(4) as pool:
        list(pool.map(lambda s: manifest.upsert(s, "ok"), ids))
    assert manifest.scene_ids() == ids
    assert manifest.store.manifests() == ["demo"]


def test_csv_export(manifest, tmp_path):
    manifest.upsert("a", "ok", artifacts={"radar_points": "ab" * 10})
    text = open(manifest.write_csv(str(tmp_path / "m.csv"))).read()
    assert text.splitlines()[0].startswith("scene_id,status,error,artifacts")
    assert '"{""radar_points"": ""abababababababababab""}"' in text


def test_rows_written_before_fallbacks_were_counted_read_as_zero(tmp_path):
    """A manifest row file of schema v1 (no ``fallbacks`` column) still reads, with 0, beside
    v2 rows; a row with a changed column is still refused."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from sim2radar.storage.schemas import MANIFEST, SchemaError

    m = ArtifactStore(tmp_path / "store").manifest("demo")
    m.upsert("new", "ok", fallbacks=3)
    m.upsert("old", "ok", artifacts={"radar_points": "ab" * 10})
    path = m._path("old")
    v1 = pq.read_table(path).drop_columns(["fallbacks"])
    v1 = v1.replace_schema_metadata({b"sim2radar.schema": b"manifest:1"})
    pq.write_table(v1, path)
    rows = {r["scene_id"]: r for r in m.rows()}
    assert rows["old"]["fallbacks"] == 0 and rows["new"]["fallbacks"] == 3
    assert m.get("old")["artifacts"] == {"radar_points": "ab" * 10}
    assert m.upsert("old", "ok")["attempts"] == 2          # and it is upgraded on its next write
    bad = v1.set_column(v1.schema.get_field_index("attempts"), "attempts",
                        pa.array(["x"], pa.string()))
    pq.write_table(bad, path)
    with pytest.raises(SchemaError, match="stored columns differ"):
        m.get("old")
    assert "fallbacks" in MANIFEST.schema.names


def test_two_processes_recording_one_scene_lose_no_attempt(tmp_path):
    """Issue #33, probe 7: two runs recording the same scene at once lost an ``attempts``
    update (read, then write); the dataset's row lock makes every upsert count."""
    import subprocess
    import sys

    code = ("import sys; from sim2radar.storage import ArtifactStore\n"
            "m = ArtifactStore(sys.argv[1]).manifest('demo')\n"
            "for _ in range(25): m.upsert('world_000001', 'ok')\n")
    procs = [subprocess.Popen([sys.executable, "-c", code, str(tmp_path / "store")])
             for _ in range(3)]
    assert [p.wait(timeout=120) for p in procs] == [0, 0, 0]
    row = ArtifactStore(tmp_path / "store").manifest("demo").get("world_000001")
    assert row["attempts"] == 75
