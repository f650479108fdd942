"""A store heals itself (issue #24): a published file that does not read — truncated, a page
damaged — is never served; it is moved into ``quarantine/`` (kept, with a note saying why) and
the run that asked recomputes it. ``verify_all`` / ``sim2radar store verify`` read everything."""

from __future__ import annotations

import logging
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from sim2radar.storage import ArtifactStore, content_key
from sim2radar.storage.store import CorruptArtifactError

KEY = content_key(stage="radar_points", stage_version=1, inputs={"scene": "s"}, config={"a": 1})


@pytest.fixture(params=["local", "memory"])
def store(request, tmp_path, memory_root):
    return ArtifactStore(tmp_path / "store" if request.param == "local" else memory_root)


def _truncate(store: ArtifactStore, path: str, keep: float = 0.5) -> bytes:
    data = store.fs.cat_file(path)
    store.fs.pipe_file(path, data[: int(len(data) * keep)])
    return data


def _damage_a_page(store: ArtifactStore, path: str) -> None:
    """Overwrite bytes in the middle of the largest column chunk: the footer still parses."""
    data = bytearray(store.fs.cat_file(path))
    with store.fs.open(path, "rb") as fh:
        meta = pq.ParquetFile(fh).metadata
    chunks = [meta.row_group(0).column(i) for i in range(meta.num_columns)]
    big = max(chunks, key=lambda c: c.total_compressed_size)
    at = big.data_page_offset + big.total_compressed_size // 2
    data[at:at + 16] = bytes(255 - b for b in data[at:at + 16])
    store.fs.pipe_file(path, bytes(data))


def test_a_truncated_artifact_is_quarantined_and_recomputed(store, frames_table, caplog):
    store.write("radar_points", KEY, frames_table)
    path = store.path("radar_points", KEY)
    original = _truncate(store, path)
    with caplog.at_level(logging.WARNING, logger="sim2radar.storage.store"):
        assert not store.exists("radar_points", KEY)  # the cache check says "recompute"
    assert path in caplog.text and "quarantine" in caplog.text
    assert not store.fs.exists(path)
    [moved] = store.quarantined()
    assert "/quarantine/radar_points/" in moved and len(store.fs.cat_file(moved)) == len(original) // 2
    why = store.fs.cat_file(f"{moved}.why.txt").decode()
    assert path in why and "Parquet" in why
    store.write("radar_points", KEY, frames_table)  # the run recomputes it ...
    assert store.exists("radar_points", KEY)  # ... and the store is whole again
    assert store.read("radar_points", KEY).num_rows == frames_table.num_rows


def test_a_damaged_page_fails_the_read_with_the_file_named_and_moves_it(store, frames_table):
    store.write("radar_points", KEY, frames_table)
    path = store.path("radar_points", KEY)
    _damage_a_page(store, path)
    assert store.exists("radar_points", KEY)  # the footer reads: only a full read finds it
    assert store.verify("radar_points", KEY, deep=False) is None
    assert "checksum verification failed" in store.verify("radar_points", KEY)  # page CRCs
    with pytest.raises(CorruptArtifactError, match="quarantine/, the next run recomputes it"):
        store.read("radar_points", KEY)
    assert not store.exists("radar_points", KEY) and len(store.quarantined()) == 1


def test_verify_all_lists_every_bad_file_and_repair_moves_them(tmp_path, frames_table):
    store = ArtifactStore(tmp_path / "store")
    keys = [content_key(stage="radar_points", stage_version=1, inputs={"i": i}, config={})
            for i in range(3)]
    for k in keys:
        store.write("radar_points", k, frames_table)
    store.manifest("d").upsert("scene-a", "ok", artifacts={"radar_points": keys[0]})
    store.manifest("d").upsert("scene-b", "ok", artifacts={"radar_points": keys[1]})
    assert store.verify_all() == []
    _truncate(store, store.path("radar_points", keys[0]))
    _damage_a_page(store, store.path("radar_points", keys[1]))
    row_file = next(p for p in (tmp_path / "store/manifests/d").iterdir() if "scene-b" in p.name)
    _truncate(store, str(row_file))
    found = store.verify_all()
    assert {Path(r["path"]).name for r in found} == {
        f"{keys[0]}.parquet", f"{keys[1]}.parquet", row_file.name}
    assert store.quarantined() == []  # listing moves nothing
    repaired = store.verify_all(repair=True)
    assert all(r["moved_to"] for r in repaired) and len(store.quarantined()) == 3
    assert store.verify_all() == [] and store.keys("radar_points") == [keys[2]]


def test_a_manifest_row_that_does_not_read_is_rebuilt_by_the_next_record(tmp_path, caplog):
    store = ArtifactStore(tmp_path / "store")
    man = store.manifest("d")
    for scene in ("a", "b"):
        man.upsert(scene, "ok", artifacts={"x": "1"})
    row_file = next(p for p in (tmp_path / "store/manifests/d").iterdir() if p.name[0] == "a")
    row_file.write_bytes(row_file.read_bytes()[:100])
    with caplog.at_level(logging.WARNING, logger="sim2radar.storage.store"):
        assert [r["scene_id"] for r in man.rows()] == ["b"]  # the others still read
    assert row_file.name in caplog.text
    assert man.get("a") is None and len(store.quarantined()) == 1
    man.upsert("a", "skipped", artifacts={"x": "1"})  # the rerun records the scene again
    assert {r["scene_id"]: r["status"] for r in man.rows()} == {"a": "skipped", "b": "ok"}


def test_store_verify_command(tmp_path, frames_table):
    from sim2radar.cli import app

    root = tmp_path / "store"
    store = ArtifactStore(root)
    store.write("radar_points", KEY, frames_table)
    run = CliRunner().invoke
    ok = run(app, ["store", "verify", str(root)])
    assert ok.exit_code == 0 and "every artifact and manifest row verifies" in ok.output
    _truncate(store, store.path("radar_points", KEY))
    bad = run(app, ["store", "verify", str(root)])
    assert bad.exit_code == 1 and f"{KEY}.parquet: not a readable Parquet file" in bad.output
    assert "--repair" in bad.output and store.quarantined() == []
    fixed = run(app, ["store", "verify", str(root), "--repair"])
    assert fixed.exit_code == 0 and "moved to" in fixed.output and len(store.quarantined()) == 1
    assert run(app, ["store", "verify", str(root)]).exit_code == 0
    missing = run(app, ["store", "verify", str(tmp_path / "nope")])
    assert missing.exit_code == 2 and "no such store folder" in missing.output


def test_a_corrupt_read_is_a_corrupt_artifact_error_subclass_of_schema_error(tmp_path,
                                                                             frames_table):
    """Callers that catch SchemaError (one bad frame fails its frame) keep working."""
    from sim2radar.storage import SchemaError

    store = ArtifactStore(tmp_path / "store")
    store.write("radar_points", KEY, frames_table)
    _truncate(store, store.path("radar_points", KEY))
    with pytest.raises(SchemaError) as info:
        store.read("radar_points", KEY)
    assert isinstance(info.value, CorruptArtifactError)


def test_a_full_disk_names_the_file_and_leaves_nothing_half_written(tmp_path, frames_table,
                                                                     monkeypatch):
    """Issue #24 probe 8: Arrow's 'No space left on device' names no file; the store's does."""
    import errno

    store = ArtifactStore(tmp_path / "store")

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pq, "write_table", full)
    with pytest.raises(OSError, match="No space left on device while writing .*radar_points"
                                      rf"/{KEY}\.parquet: free space") as info:
        store.write("radar_points", KEY, frames_table)
    assert info.value.errno == errno.ENOSPC
    assert not store.exists("radar_points", KEY) and store.partial_files() == []
