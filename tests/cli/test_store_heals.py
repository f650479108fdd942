"""A damaged store heals on one rerun (issue #24, probes 1 and 2), through real ``sim2radar
generate`` processes (2 worlds x 2 frames, both geometries, OpenPCDet export, ~11 s a run):

* a truncated manifest row (the probe: ``truncate -s 2270`` a world's row) and a truncated file
  of every stage — world specs and frames, depth maps, segmentations, material labels, the
  reconstruction, scene meshes, dataset frames — then one rerun: exit 0, no traceback, one
  warning line per file naming it, every damaged file kept in ``quarantine/``, the export
  identical to an untouched run's and ``sim2radar store verify`` clean;
* ``store verify`` finds a file a cached rerun would not read (a damaged page with a good
  footer); ``--repair`` moves it aside and the next run recomputes it.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from sim2radar.storage import ArtifactStore
from tests.cli.test_kill_and_rerun import _export_files

REPO = Path(__file__).resolve().parents[2]
ARGS = ["generate", "--worlds", "2", "--frames", "2", "--width", "80", "--height", "60",
        "--spp", "2", "--geometry", "both", "--no-png", "--no-prefect"]
CLI = [sys.executable, "-c", "from sim2radar.cli import main; main()"]
STAGES = ("world_specs", "world_frames", "depth_maps", "segmentations", "material_labels",
          "reconstruction", "scene_meshes", "dataset_frames")


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], cwd=REPO, capture_output=True, text=True, timeout=300)


def _generate(store: Path, export: Path) -> subprocess.CompletedProcess:
    proc = _run(*ARGS, "--out", str(store), "--export-openpcdet", str(export))
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert "Traceback" not in proc.stdout + proc.stderr
    return proc


@pytest.fixture(scope="module")
def untouched(tmp_path_factory):
    root = tmp_path_factory.mktemp("untouched")
    _generate(root / "store", root / "export")
    return root / "store", root / "export"


def test_a_truncated_manifest_and_a_truncated_file_of_every_stage_heal_on_one_rerun(
        untouched, tmp_path):
    store, export = tmp_path / "store", tmp_path / "export"
    shutil.copytree(untouched[0], store)
    damaged = []
    world_row = next((store / "manifests" / "generated").glob("world_000000-*.parquet"))
    world_row.write_bytes(world_row.read_bytes()[:2270])  # the probe's truncate -s 2270
    damaged.append(world_row)
    for stage in STAGES:
        path = sorted((store / stage).glob("*.parquet"))[-1]
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
        damaged.append(path)

    proc = _generate(store, export)
    log = proc.stdout + proc.stderr
    for path in damaged:
        assert f"{path} does not verify" in " ".join(log.split()), path
    assert _export_files(export) == _export_files(untouched[1])
    st = ArtifactStore(store)
    moved = st.quarantined()
    assert sorted(Path(m).name.split(".parquet")[0] for m in moved) == sorted(
        p.stem for p in damaged)  # every damaged file kept, none deleted
    rows = st.manifest("generated").rows()
    assert len(rows) == 6 and {r["status"] for r in rows} <= {"ok", "skipped"}
    check = _run("store", "verify", str(store))
    assert check.returncode == 0, check.stdout + check.stderr
    # healed for good: a third run finds everything cached and moves nothing more
    again = _generate(store, tmp_path / "export2")
    assert "does not verify" not in again.stdout + again.stderr
    assert {r["status"] for r in st.manifest("generated").rows()} == {"skipped"}


def test_store_verify_finds_damage_a_cached_run_would_not_read(untouched, tmp_path):
    store = tmp_path / "store"
    shutil.copytree(untouched[0], store)
    # a depth map whose footer is intact but whose pages are not: caches check footers only
    path = sorted((store / "depth_maps").glob("*.parquet"))[0]
    data = bytearray(path.read_bytes())
    data[200:232] = bytes(255 - b for b in data[200:232])
    path.write_bytes(bytes(data))
    found = _run("store", "verify", str(store))
    assert found.returncode == 1 and "Traceback" not in found.stdout + found.stderr
    assert str(path) in " ".join(found.stdout.split())
    repaired = _run("store", "verify", str(store), "--repair")
    assert repaired.returncode == 0 and "moved to" in repaired.stdout
    assert not path.exists() and len(ArtifactStore(store).quarantined()) == 1
    _generate(store, tmp_path / "export")
    assert path.exists()  # recomputed by the next run
    assert _export_files(tmp_path / "export") == _export_files(untouched[1])
    final = _run("store", "verify", str(store))
    assert final.returncode == 0, final.stdout + final.stderr[-3000:]
