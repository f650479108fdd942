"""ArtifactStore: validated round trips, atomic publish, provenance, retries, memory:// URIs."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from sim2radar.storage import (
    ArtifactNotFoundError,
    ArtifactStore,
    SchemaError,
    content_key,
    file_digest,
    radar_frames_from_table,
)

KEY = content_key(stage="radar_points", stage_version=1, inputs={"scene": "s"}, config={"a": 1})
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(params=["local", "memory"])
def store(request, tmp_path, memory_root):
    return ArtifactStore(tmp_path / "store" if request.param == "local" else memory_root)


def test_round_trip_is_exact_and_validated(store, frames_table):
    assert not store.exists("radar_points", KEY)
    where = store.write("radar_points", KEY, frames_table, stage_version=1)
    assert KEY in where and store.exists("radar_points", KEY)
    assert store.keys("radar_points") == [KEY]
    back = store.read("radar_points", KEY)
    assert back.drop_columns([]).equals(frames_table.select(back.column_names).cast(back.schema))
    frames = radar_frames_from_table(back)
    np.testing.assert_array_equal(
        frames[0].points, radar_frames_from_table(frames_table)[0].points
    )
    assert store.read("radar_points", KEY, columns=["n_points"]).column(0).to_pylist() == [50, 3]


def test_schema_violations_are_refused_with_the_column_named(store, frames_table):
    with pytest.raises(SchemaError, match=r"missing \['sim_seconds'\]"):
        store.write("radar_points", KEY, frames_table.drop_columns(["sim_seconds"]))
    bad = frames_table.set_column(
        frames_table.schema.get_field_index("scene_id"), "scene_id", pa.array([1.5, 2.5])
    )
    with pytest.raises(SchemaError, match="'scene_id'"):
        store.write("radar_points", KEY, bad)
    nulls = frames_table.set_column(
        frames_table.schema.get_field_index("sim_seconds"), "sim_seconds", pa.array([None, 1.0])
    )
    with pytest.raises(SchemaError, match="null"):
        store.write("radar_points", KEY, nulls)
    with pytest.raises(SchemaError, match="no schema declared for stage 'nope'"):
        store.write("nope", KEY, frames_table)
    assert not store.exists("radar_points", KEY)
    # lossless conversions are applied: int64 frame_index -> declared int32
    wide = frames_table.set_column(1, "frame_index", pa.array([0, 1], pa.int64()))
    store.write("radar_points", KEY, wide)
    assert store.read("radar_points", KEY).schema.field("frame_index").type == pa.int32()


def test_reading_a_missing_or_foreign_file_fails_clearly(tmp_path, frames_table):
    store = ArtifactStore(tmp_path)
    with pytest.raises(ArtifactNotFoundError, match="does not exist"):
        store.read("radar_points", KEY)
    # a file written by "another code version" (no/other schema tag) is refused, not misread
    path = Path(store.path("radar_points", KEY))
    path.parent.mkdir(parents=True)
    pq.write_table(frames_table, path)
    with pytest.raises(SchemaError, match="bump the stage version"):
        store.read("radar_points", KEY)


def test_provenance_records_config_seed_versions_timings_and_model_hashes(store, frames_table, tmp_path):
    model = tmp_path / "model.onnx"
    model.write_bytes(b"weights")
    store.write(
        "radar_points",
        KEY,
        frames_table,
        stage_version=1,
        provenance={
            "inputs": {"scene": "s"},
            "config": {"a": 1, "radar": {"bandwidth_hz": np.float64(3.95e9)}},
            "seed": 7,
            "timings_s": {"simulate": 0.5},
            "model_files": {"depth": file_digest(model)},
            "note": "kept under extra",
        },
    )
    prov = store.read_provenance("radar_points", KEY)
    assert prov["key"] == KEY and prov["stage"] == "radar_points"
    assert prov["stage_version"] == 1 and prov["schema_version"] == 1
    assert prov["seed"] == 7 and prov["config"]["radar"]["bandwidth_hz"] == 3.95e9
    assert prov["timings_s"] == {"simulate": 0.5}
    assert prov["model_files"]["depth"] == file_digest(model)
    assert prov["extra"] == {"note": "kept under extra"}
    for pkg in ("mitsuba", "drjit", "torch", "numpy", "pyarrow", "sim2radar"):
        assert pkg in prov["versions"]
    assert prov["versions"]["pyarrow"] == pa.__version__


def test_crash_mid_write_leaves_no_visible_artifact(store, frames_table, monkeypatch):
    real_write = pq.write_table

    def half_write(table, where, **kw):
        real_write(table.slice(0, 1), where, **kw)  # some bytes reach the temporary file ...
        raise OSError("disk full")  # ... then the writer dies

    monkeypatch.setattr(pq, "write_table", half_write)
    with pytest.raises(OSError, match="disk full"):
        store.write("radar_points", KEY, frames_table)
    assert not store.exists("radar_points", KEY)
    assert store.keys("radar_points") == []
    assert store.partial_files() == []  # the failed writer cleaned up after itself


def test_killed_process_leaves_only_an_ignored_tmp_file(tmp_path, frames_table):
    """A writer killed (os._exit) mid-write: readers see nothing; clean_partial removes the rest."""
    root = tmp_path / "store"
    script = textwrap.dedent(
        f"""
        import os, numpy as np, pyarrow.parquet as pq
        from sim2radar.storage import ArtifactStore, radar_frames_to_table
        real = pq.write_table
        def dying(table, where, **kw):
            real(table, where, **kw)
            where.flush()
            os._exit(9)   # killed after the bytes are written but before the rename
        pq.write_table = dying
        t = radar_frames_to_table(scene_id="s", radar_to_world=[np.eye(4)],
                                  points=[np.zeros((5, 4), np.float32)])
        ArtifactStore({str(root)!r}).write("radar_points", {KEY!r}, t)
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 9, proc.stderr
    store = ArtifactStore(root)
    assert not store.exists("radar_points", KEY)
    assert store.keys("radar_points") == []
    with pytest.raises(ArtifactNotFoundError):
        store.read("radar_points", KEY)
    partial = store.partial_files()
    assert len(partial) == 1 and os.path.getsize(partial[0]) > 0
    assert store.clean_partial(older_than_s=3600) == []  # too fresh: maybe a live writer
    assert store.clean_partial(older_than_s=0) == partial
    assert store.partial_files() == []


def test_remote_io_is_retried_local_io_is_not(memory_root, tmp_path, frames_table, monkeypatch):
    remote = ArtifactStore(memory_root, retry_backoff_s=0.0)
    assert remote.io_retries == 3 and not remote.is_local
    calls = {"n": 0}
    real_exists = remote.fs.exists

    def flaky_exists(path, **kw):
        calls["n"] += 1
        if calls["n"] <= 2:
            raise ConnectionError("transient network error")
        return real_exists(path, **kw)

    monkeypatch.setattr(remote.fs, "exists", flaky_exists)
    assert remote.exists("radar_points", KEY) is False
    assert calls["n"] == 3

    local = ArtifactStore(tmp_path, retry_backoff_s=0.0)
    assert local.io_retries == 0 and local.is_local
    monkeypatch.setattr(local.fs, "exists", lambda *a, **k: (_ for _ in ()).throw(OSError("io")))
    with pytest.raises(OSError, match="io"):
        local.exists("radar_points", KEY)


def test_bad_keys_and_store_pickles(tmp_path):
    import pickle

    store = ArtifactStore(tmp_path)
    with pytest.raises(ValueError, match="lowercase hex"):
        store.path("radar_points", "../etc/passwd")
    clone = pickle.loads(pickle.dumps(store))
    assert clone.root == store.root and clone.is_local


def test_check_writable_names_the_path_and_the_fix(tmp_path, unwritable_dir, memory_root):
    from sim2radar.storage import check_writable

    check_writable(tmp_path / "new" / "store")  # missing folders are fine: a parent is writable
    assert not (tmp_path / "new").exists()  # and the check created nothing
    check_writable(memory_root)  # remote URIs are not probed
    with pytest.raises(PermissionError) as info:
        check_writable(unwritable_dir / "store")
    msg = str(info.value)
    assert str(unwritable_dir / "store") in msg and "not writable" in msg
    assert "choose a writable folder or fix its permissions" in msg
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(ValueError, match="a_file is a file, not a folder"):
        check_writable(tmp_path / "a_file" / "store")


def test_permanent_io_errors_are_not_retried(memory_root, monkeypatch):
    import errno

    from sim2radar.storage import is_transient_io_error

    assert is_transient_io_error(ConnectionError("reset")) and is_transient_io_error(TimeoutError())
    for exc in (PermissionError(errno.EACCES, "denied"), OSError(errno.EROFS, "read-only"),
                OSError(errno.ENOSPC, "full"), FileNotFoundError("gone"), ValueError("bad")):
        assert not is_transient_io_error(exc), exc
    remote = ArtifactStore(memory_root, retry_backoff_s=0.0)
    calls = {"n": 0}

    def denied(path, **kw):
        calls["n"] += 1
        raise PermissionError(errno.EACCES, "Access Denied", path)

    monkeypatch.setattr(remote.fs, "exists", denied)
    with pytest.raises(PermissionError):
        remote.exists("radar_points", KEY)
    assert calls["n"] == 1  # no retries: the answer would be the same
