"""`generate --retry-failed`: only what the manifest records as failed runs again; the export
then covers the whole dataset."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.storage import ArtifactStore


def _invoke(args):
    return CliRunner().invoke(app, args, env={"COLUMNS": "400"})


def test_retry_failed_worlds_reruns_only_them(tmp_path, monkeypatch):
    import sim2radar.tasks.worlds

    real = sim2radar.tasks.worlds.generate_world_artifacts

    def flaky(seed, *a, **k):
        if seed == 1:
            raise OSError("disk hiccup while rendering world 1")
        return real(seed, *a, **k)

    store, export = tmp_path / "store", tmp_path / "opcd"
    args = ["generate", "--no-prefect", "--no-png", "--worlds", "2", "--frames", "1",
            "--geometry", "ground_truth", "--width", "64", "--height", "48", "--spp", "1",
            "--out", str(store), "--dataset", "d", "--export-openpcdet", str(export)]
    monkeypatch.setattr(sim2radar.tasks.worlds, "generate_world_artifacts", flaky)
    first = _invoke(args + ["--json", str(tmp_path / "first.json")])
    assert first.exit_code == 1 and "1 of 2 worlds failed" in first.output, first.output
    rows = {r["scene_id"]: r for r in ArtifactStore(store).manifest("d").rows()}
    assert rows["world_000001"]["status"] == "failed"
    monkeypatch.setattr(sim2radar.tasks.worlds, "generate_world_artifacts", real)

    seen = []
    monkeypatch.setattr(sim2radar.tasks.worlds, "generate_world_artifacts",
                        lambda seed, *a, **k: seen.append(seed) or real(seed, *a, **k))
    again = _invoke(args + ["--retry-failed", "--json", str(tmp_path / "again.json")])
    assert again.exit_code == 0, again.output
    assert seen == [1]  # world 0 was not touched
    summary = json.loads((tmp_path / "again.json").read_text())
    assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 0}
    rows = {r["scene_id"]: r for r in ArtifactStore(store).manifest("d").rows()}
    assert rows["world_000001"]["status"] == "ok" and rows["world_000000"]["attempts"] == 1
    assert sorted(p.stem for p in (export / "points").glob("*.npy")) == \
        ["world_000000_f000", "world_000001_f000"]

    nothing = _invoke(args + ["--retry-failed"])
    assert nothing.exit_code == 0 and "nothing to retry" in nothing.output


def test_retry_failed_needs_an_existing_dataset(tmp_path):
    res = _invoke(["generate", "--no-prefect", "--retry-failed", "--out", str(tmp_path / "s"),
                   "--dataset", "nope"])
    assert res.exit_code == 2 and "no manifest rows" in res.output, res.output


@pytest.mark.parametrize("with_prefect", [False])
def test_retry_failed_capture_scene(tmp_path, with_prefect):
    caps = tmp_path / "caps"
    res = _invoke(["worlds", "captures", "--out", str(caps), "--worlds", "1", "--first-seed",
                   "6", "--width", "160", "--height", "120", "--spp", "4"])
    assert res.exit_code == 0, res.output
    (caps / "scene_late").mkdir()
    for name in ("rgb.png", "intrinsics.yaml"):  # no LiDAR yet: its depth step fails
        shutil.copy(caps / "scene_006" / name, caps / "scene_late" / name)
    cfg = tmp_path / "gen.yaml"
    cfg.write_text("poses: {frames: 2}\n")
    args = ["generate", "--captures", str(caps), "--no-prefect", "--no-png", "--config",
            str(cfg), "--out", str(tmp_path / "store"), "--export-openpcdet",
            str(tmp_path / "opcd")]
    first = _invoke(args + ["--allow-failures"])
    assert first.exit_code == 0 and "[depth]" in first.output, first.output
    shutil.copy(caps / "scene_006" / "lidar.npy", caps / "scene_late" / "lidar.npy")
    again = _invoke(args + ["--retry-failed", "--json", str(tmp_path / "again.json")])
    assert again.exit_code == 0, again.output
    summary = json.loads((tmp_path / "again.json").read_text())
    assert [w["id"] for w in summary["outcomes"]] == ["scene_late"]
    assert summary["counts"]["ok"] == 1, summary["outcomes"][0]["error"]
    assert len(list((tmp_path / "opcd" / "points").glob("*.npy"))) == 4  # both scenes
