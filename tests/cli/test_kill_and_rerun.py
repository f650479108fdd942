"""What a killed or doubled ``sim2radar generate`` leaves behind (issue #16: "must keep holding").

Real ``generate`` processes on one tiny dataset (2 worlds x 3 frames, ground-truth geometry,
OpenPCDet export), compared with one uninterrupted run:

* killed with SIGKILL in the middle of a world, then run again;
* ended hard (``os._exit``, what SIGKILL leaves) in the middle of the OpenPCDet export, with a
  half-written temporary file, then run again;
* two runs started at once on the same store.

Each time every Parquet file of the store reads, the store lists no in-flight file, the
manifest has one row per scene and frame, the frames finished before a kill are ``skipped`` by
the rerun, and the dataset (frame content and the export's files) is identical to the
uninterrupted run's. The plain loop (``--no-prefect``) keeps this at ~40 s on 2 cores; the
Prefect path writes through the same functions, and its kill is in ``test_server.py``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from sim2radar.storage import ArtifactStore
from sim2radar.tasks.dataset import read_dataset_frame

REPO = Path(__file__).resolve().parents[2]
ARGS = ["generate", "--worlds", "2", "--frames", "3", "--width", "80", "--height", "60",
        "--spp", "2", "--geometry", "ground_truth", "--no-png", "--no-prefect"]
MAIN = "from sim2radar.cli import main; main()"
# the export ends the process hard while it writes its 4th file: the temporary file is written,
# the rename never happens (what a SIGKILL at that instant leaves)
DIE_IN_EXPORT = """
import os, sim2radar.datasets.openpcdet as opd
calls, write = [0], opd.atomic_write
def dying_write(path, data):
    calls[0] += 1
    if calls[0] == 4:
        path.with_name(f".{path.name}.tmp{os.getpid()}").write_bytes(data[: len(data) // 2])
        os._exit(137)
    return write(path, data)
opd.atomic_write = dying_write
""" + MAIN


def _generate(store: Path, export: Path, code: str = MAIN, **popen) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code, *ARGS, "--out", str(store),
                             "--export-openpcdet", str(export)], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)


def _finish(proc: subprocess.Popen) -> None:
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, out[-2000:] + err[-3000:]


def _published_frames(store: Path) -> set[str]:
    """Keys of the frames a run has published (in-flight ``.tmp-*`` files are not frames)."""
    return {p.stem for p in store.glob("dataset_frames/*.parquet") if not p.name.startswith(".")}


def _frames(store: Path) -> dict[str, str]:
    """frame row -> its dataset_frames key, from the manifest (asserting one row per id)."""
    rows = ArtifactStore(store).manifest("generated").rows()
    ids = [r["scene_id"] for r in rows]
    assert len(ids) == len(set(ids)), "duplicate manifest rows"
    return {r["scene_id"]: r["artifacts"]["dataset_frames/ground_truth"]
            for r in rows if "_f" in r["scene_id"]}


def _status(store: Path) -> dict[str, str]:
    return {r["scene_id"]: r["status"] for r in ArtifactStore(store).manifest("generated").rows()}


def _export_files(export: Path) -> dict[str, bytes]:
    """Every file of an export (hidden ones included) -> bytes; dataset.json without the
    fields that name the time or the folder."""
    out = {}
    for p in sorted(export.rglob("*")):
        if p.is_file():
            data = p.read_bytes()
            if p.name == "dataset.json":
                doc = json.loads(data)
                doc.pop("exported_at"), doc.pop("root")
                data = json.dumps(doc, sort_keys=True).encode()
            out[str(p.relative_to(export))] = data
    return out


def _assert_same_dataset(store: Path, export: Path, ref_store: Path, ref_export: Path) -> None:
    st = ArtifactStore(store)
    for path in store.rglob("*.parquet"):
        if not path.name.startswith("."):  # in-flight names (.tmp-*) are never read
            pq.read_table(path)  # every published file reads
    frames, ref = _frames(store), _frames(ref_store)
    assert frames == ref  # the same frames under the same content keys
    for key in frames.values():
        a, b = read_dataset_frame(st, key), read_dataset_frame(ref_store, key)
        assert a.points.tobytes() == b.points.tobytes()
        assert np.array_equal(a.boxes, b.boxes) and a.box_labels == b.box_labels
    assert _export_files(export) == _export_files(ref_export)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One uninterrupted run."""
    root = tmp_path_factory.mktemp("reference")
    proc = _generate(root / "store", root / "export")
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, out[-2000:] + err[-3000:]
    assert len(_frames(root / "store")) == 6
    # two worlds cannot fill train, val and test (split by world): said, not silent
    meta = json.loads((root / "export" / "dataset.json").read_text())
    assert [k for k, n in meta["splits"].items() if n == 0] and "are empty" in meta["warnings"][0]
    assert "are empty" in out + err
    return root / "store", root / "export"


def test_a_run_killed_mid_world_then_rerun_is_the_uninterrupted_dataset(reference, tmp_path):
    store, export = tmp_path / "store", tmp_path / "export"
    proc = _generate(store, export)
    deadline = time.monotonic() + 240
    while not _published_frames(store) and proc.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, "the run ended before it was killed"
    done = _published_frames(store)
    assert 0 < len(done) < 6 and not export.exists()

    _finish(_generate(store, export))
    status, frames = _status(store), _frames(store)
    assert {status[f] for f, key in frames.items() if key in done} == {"skipped"}
    assert {status[f] for f, key in frames.items() if key not in done} == {"ok"}
    _assert_same_dataset(store, export, *reference)


def test_a_run_ended_mid_export_then_rerun_is_the_uninterrupted_export(reference, tmp_path):
    store, export = tmp_path / "store", tmp_path / "export"
    proc = _generate(store, export, code=DIE_IN_EXPORT)
    proc.communicate(timeout=300)
    assert proc.returncode == 137
    assert list(export.rglob(".*.tmp*")), "the export was not cut mid-write"
    assert not (export / "dataset.json").exists()

    _finish(_generate(store, export))
    assert set(_status(store).values()) == {"skipped"}
    assert not list(export.rglob(".*.tmp*"))  # the dead run's temporary file is gone
    _assert_same_dataset(store, export, *reference)


def test_two_runs_at_once_on_one_store_give_the_dataset_of_one(reference, tmp_path):
    store = tmp_path / "store"
    runs = [_generate(store, tmp_path / f"export{i}") for i in range(2)]
    for proc in runs:
        _finish(proc)
    for i in range(2):
        _assert_same_dataset(store, tmp_path / f"export{i}", *reference)
