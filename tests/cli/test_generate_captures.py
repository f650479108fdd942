"""`sim2radar generate --captures`: a capture folder to an OpenPCDet dataset in one command;
procedural-only options and bad folders are one line, exit 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from sim2radar.cli import app


@pytest.fixture(scope="module")
def one_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("caps")
    res = CliRunner().invoke(app, ["worlds", "captures", "--out", str(root), "--worlds", "1",
                                   "--first-seed", "4", "--width", "160", "--height", "120",
                                   "--spp", "4"])
    assert res.exit_code == 0, res.output
    return root


@pytest.mark.parametrize("extra, message", [
    (["--worlds", "2"], "['--worlds'] describe procedural worlds"),
    (["--geometry", "both"], "['--geometry'] describe procedural worlds"),
])
def test_procedural_options_are_refused(one_scene, tmp_path, extra, message):
    res = CliRunner().invoke(app, ["generate", "--captures", str(one_scene), "--no-prefect",
                                   "--out", str(tmp_path / "store"), *extra],
                             env={"COLUMNS": "400"})
    assert res.exit_code == 2 and message in res.output, res.output
    assert "Traceback" not in res.output


def test_missing_capture_folder_is_one_line(tmp_path):
    res = CliRunner().invoke(app, ["generate", "--captures", str(tmp_path / "none"),
                                   "--no-prefect", "--out", str(tmp_path / "store")],
                             env={"COLUMNS": "400"})
    assert res.exit_code == 2 and "capture folder not found" in res.output, res.output


def test_a_misnamed_vlm_model_stops_generate_before_any_work(one_scene, tmp_path):
    """Both entry points that reconstruct ask the VLM server first: `generate --captures` and
    procedural `generate` exit 2 with one line naming the served models, before any frame."""
    import yaml

    from tests.reconstruct._vlm_server import VlmTestServer

    with VlmTestServer("json", served_models=("/models/internvl",)) as srv:
        cfg = tmp_path / "vlm.yaml"
        cfg.write_text(yaml.safe_dump({"materials": {"name": "vlm", "options": {
            "base_url": srv.base_url, "model": "OpenGVLab/InternVL2_5-8B",
            "on_error": "unknown"}}}))
        for args in (["--captures", str(one_scene)], ["--worlds", "1", "--frames", "1"]):
            res = CliRunner().invoke(app, ["generate", *args, "--no-prefect", "--reconstruction",
                                           str(cfg), "--out", str(tmp_path / "store")],
                                     env={"COLUMNS": "400"})
            assert res.exit_code == 2, res.output
            assert "error: materials (vlm): the server at" in res.output
            assert "not 'OpenGVLab/InternVL2_5-8B'" in res.output
            assert "Traceback" not in res.output
        assert srv.n_requests == 0 and srv.model_queries == 2
    assert not (tmp_path / "store" / "manifests").exists()


def test_capture_folder_to_openpcdet_in_one_command(one_scene, tmp_path):
    cfg = tmp_path / "gen.yaml"
    cfg.write_text("poses: {frames: 3, forward_m: [0.0, 1.5]}\nseed: 2\n")
    export = tmp_path / "opcd"
    res = CliRunner().invoke(app, ["generate", "--captures", str(one_scene), "--no-prefect",
                                   "--config", str(cfg), "--out", str(tmp_path / "store"),
                                   "--export-openpcdet", str(export), "--json",
                                   str(tmp_path / "summary.json")], env={"COLUMNS": "400"})
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 0}
    assert summary["frame_counts"]["ok"] == 3 and summary["unit"] == "scenes"
    ids = sorted(p.stem for p in (export / "points").glob("*.npy"))
    assert ids == ["scene_004_f000", "scene_004_f001", "scene_004_f002"]
    assert np.load(export / "points" / f"{ids[0]}.npy").shape[1] == 4
    assert "seconds per step" in res.output and "GT doors" not in res.output
    assert (tmp_path / "bev" / "scene_004_rec.png").is_file()
    # one scene cannot fill val and test: said, not silent
    assert "warning:" in res.output and "are empty" in res.output
    meta = json.loads((export / "dataset.json").read_text())
    assert any("['val', 'test'] are empty" in w for w in meta["warnings"])


def test_bad_radar_yaml_fails_its_scene_in_one_line_while_the_others_finish(one_scene, tmp_path):
    """Issue #24, the probe's steps through `generate --captures`: a scene whose radar.yaml
    has a singular `radar_from_camera` and one whose matrix is scaled (non-rigid) each fail
    in one line naming the file, the field and the fix (no `LinAlgError`, no per-frame
    `pose[:3, :3] must be a rotation`); a scene folder named `...` is skipped with a warning;
    a scene reached through a symlink out of the folder runs, with a line naming the link."""
    import shutil

    import yaml

    src = one_scene / "scene_004"
    caps = tmp_path / "caps"
    caps.mkdir()
    (caps / "linked").symlink_to(src, target_is_directory=True)
    for name, matrix in (("singular", np.diag([1.0, 1.0, 0.0, 1.0])),
                         ("scaled", np.diag([1.1, 1.1, 1.1, 1.0]))):
        shutil.copytree(src, caps / name)
        (caps / name / "radar.yaml").write_text(
            yaml.safe_dump({"radar_from_camera": matrix.tolist()}))
    shutil.copytree(src, caps / "...")
    # a real process: the warnings go where a user sees them (stderr), not into a test's log
    run = subprocess.run([sys.executable, "-c", "from sim2radar.cli import main; main()",
                          "generate", "--captures", str(caps), "--no-prefect", "--frames", "1",
                          "--no-png", "--out", str(tmp_path / "store"), "--json",
                          str(tmp_path / "summary.json")], capture_output=True, text=True,
                         env={**os.environ, "COLUMNS": "1000"}, timeout=300)
    output = run.stdout + run.stderr
    assert run.returncode == 1, output  # two scenes failed
    assert "2 of 3 scenes failed" in output
    assert "Traceback" not in output and "LinAlgError" not in output
    assert "must be a rotation" not in output
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 2}
    assert summary["frame_counts"]["ok"] == 1
    failed = {w["id"]: w for w in summary["outcomes"] if w["status"] == "failed"}
    assert sorted(failed) == ["scaled", "singular"]
    for name, why in (("singular", "its rotation part is singular (det 0)"),
                      ("scaled", "its rotation part is not orthonormal")):
        line = next(ln for ln in output.splitlines() if f"✗ {name}:" in ln)
        path = caps / name / "radar.yaml"
        assert f"[inputs] ValueError: {path}: radar_from_camera is not a rigid transform: " \
               f"{why}" in line, line
        assert "give radar_from_camera as a 4x4 rigid transform" in line
        assert failed[name]["parts"] == []  # refused before any reconstruction or frame
    lines = output.splitlines()
    hidden = [ln for ln in lines if "skipped folder '...'" in ln]
    assert len(hidden) == 1 and "rename it without the leading dot" in hidden[0], output
    linked = [ln for ln in lines if f"{caps / 'linked'} is a symlink to {src}" in ln]
    assert len(linked) == 1 and "following it" in linked[0], output


def test_a_vlm_outage_is_never_cached_as_a_result(one_scene, tmp_path):
    """Issue #33, probe 1: with on_error: unknown a server answering garbage labels every
    segment unknown; the run finishes (exit 0; --strict exit 1), counts the fallbacks in the
    summary and the manifest, and stores them as provisional: a rerun against the same server,
    healthy again, asks again, gets the right materials and simulates the frames again
    (fallbacks N -> 0); a third run makes no request."""
    import yaml

    from sim2radar.storage import ArtifactStore
    from sim2radar.storage.reconstruction import materials_from_table
    from tests.reconstruct._vlm_server import VlmTestServer

    store = tmp_path / "store"
    gen = tmp_path / "gen.yaml"
    gen.write_text("poses: {frames: 2, forward_m: [0.0, 1.0]}\nseed: 2\n")

    def run(*extra):
        res = CliRunner().invoke(app, ["generate", "--captures", str(one_scene), "--no-prefect",
                                       "--config", str(gen), "--reconstruction", str(cfg),
                                       "--out", str(store), "--no-png", "--json",
                                       str(tmp_path / "s.json"), *extra],
                                 env={"COLUMNS": "400"})
        return res, json.loads((tmp_path / "s.json").read_text())

    with VlmTestServer("garbage") as srv:
        cfg = tmp_path / "vlm.yaml"
        cfg.write_text(yaml.safe_dump({"materials": {"name": "vlm", "options": {
            "base_url": srv.base_url, "model": "test-vlm", "on_error": "unknown",
            "max_retries": 0}}}))
        res, summary = run()
        assert res.exit_code == 0, res.output
        asked = srv.n_requests
        assert asked > 0
        fb = summary["fallbacks"]
        assert fb["segments"] == asked and fb["scenes"] == 1 and fb["frames"] == 2, fb
        assert "fell back to unknown" in res.output
        st = ArtifactStore(store)
        rows = {r["scene_id"]: r for r in st.manifest("captures").rows()}
        assert rows["scene_004"]["fallbacks"] == asked
        assert rows["scene_004_f000"]["fallbacks"] == asked
        mkey = summary["outcomes"][0]["artifacts"]["material_labels"]
        labels, _, _ = materials_from_table(st.read("material_labels", mkey))
        assert {m.material for m in labels} == {"unknown"}
        assert st.provisional("material_labels", mkey)["fallbacks"] == asked
        assert not st.cached("material_labels", mkey)

        res, _ = run("--strict")               # --strict fails on fallbacks; asked again
        assert res.exit_code == 1, res.output
        assert srv.n_requests == 2 * asked

        srv.mode = "json"                      # healthy again: right materials, new frames
        res, summary = run("--strict")
        assert res.exit_code == 0, res.output
        assert srv.n_requests == 3 * asked
        assert summary["fallbacks"] == {"segments": 0, "frames": 0, "scenes": 0}
        assert summary["counts"]["ok"] == 1 and summary["frame_counts"]["ok"] == 2
        labels, _, _ = materials_from_table(st.read("material_labels", mkey))
        assert "unknown" not in {m.material for m in labels}, labels
        assert st.cached("material_labels", mkey) and st.provisional("material_labels",
                                                                     mkey) is None
        rows = {r["scene_id"]: r for r in st.manifest("captures").rows()}
        assert rows["scene_004"]["fallbacks"] == 0 and rows["scene_004_f001"]["fallbacks"] == 0
        for f in summary["outcomes"][0]["parts"]:
            assert st.cached("dataset_frames", f["artifacts"]["dataset_frames/reconstructed"])

        res, summary = run()                   # a result now: nothing asked, nothing made
        assert res.exit_code == 0 and srv.n_requests == 3 * asked
        assert summary["counts"]["skipped"] == 1 and summary["frame_counts"]["skipped"] == 2


def test_a_vlm_outage_in_procedural_worlds_is_asked_again(tmp_path):
    """The same through procedural `generate` (reconstructed geometry, frames fused with the
    earlier frame): the world and its frames count the fallbacks, the rerun against the
    healthy server asks again and re-simulates the frames."""
    import yaml

    from tests.reconstruct._vlm_server import VlmTestServer

    gen = tmp_path / "gen.yaml"
    gen.write_text("geometry: reconstructed\nrig: {width: 160, height: 120, spp: 2}\n")
    with VlmTestServer("oov") as srv:
        cfg = tmp_path / "vlm.yaml"
        cfg.write_text(yaml.safe_dump({"materials": {"name": "vlm", "options": {
            "base_url": srv.base_url, "model": "test-vlm", "on_error": "unknown"}},
            "fusion": {"frames": 1}}))

        def run():
            res = CliRunner().invoke(app, [
                "generate", "--worlds", "1", "--frames", "2", "--no-prefect", "--no-png",
                "--config", str(gen), "--reconstruction", str(cfg),
                "--out", str(tmp_path / "store"), "--json", str(tmp_path / "s.json")],
                env={"COLUMNS": "400"})
            assert res.exit_code == 0, res.output
            return json.loads((tmp_path / "s.json").read_text())

        summary = run()
        asked = srv.n_requests
        assert asked > 0 and summary["fallbacks"]["segments"] == asked
        assert summary["fallbacks"]["frames"] == 2 and summary["fallbacks"]["scenes"] == 1
        srv.mode = "json"
        summary = run()
        assert srv.n_requests == 2 * asked
        assert summary["fallbacks"]["segments"] == 0
        assert summary["frame_counts"]["ok"] == 2
        summary = run()
        assert srv.n_requests == 2 * asked and summary["frame_counts"]["skipped"] == 2


def test_names_that_would_break_the_layout_are_refused_where_they_enter(one_scene, tmp_path):
    """Issue #33, probe 2 and 6: a scene folder whose name holds a newline is skipped with one
    line naming it and the rule (its id would split ImageSets lines); a folder named with
    spaces and unicode still works; a 300-character --dataset is refused before any work."""
    import shutil

    from sim2radar.factory.captures import find_captures

    caps = tmp_path / "caps"
    caps.mkdir()
    shutil.copytree(one_scene / "scene_004", caps / "Büro 3")
    shutil.copytree(one_scene / "scene_004", caps / "bad\nname")
    shutil.copytree(one_scene / "scene_004", caps / ("x" * 130))
    scenes = find_captures(caps, warn=False)
    assert [s.scene_id for s in scenes] == ["Büro 3"]
    export = tmp_path / "opcd"
    res = CliRunner().invoke(app, ["generate", "--captures", str(caps), "--no-prefect",
                                   "--frames", "1", "--no-png", "--out", str(tmp_path / "store"),
                                   "--export-openpcdet", str(export)], env={"COLUMNS": "400"})
    assert res.exit_code == 0, res.output
    lines = [x for f in (export / "ImageSets").glob("*.txt") for x in f.read_text().splitlines()]
    assert lines == ["Büro 3_f000"]
    assert (export / "points" / "Büro 3_f000.npy").is_file()
    res = CliRunner().invoke(app, ["generate", "--captures", str(caps), "--no-prefect",
                                   "--dataset", "d" * 300, "--out", str(tmp_path / "store2")],
                             env={"COLUMNS": "400"})
    assert res.exit_code == 2, res.output
    assert "at most 100 characters" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "store2" / "depth_maps").exists()


def test_an_id_rule_names_what_is_wrong():
    from sim2radar.vocab import id_problem

    for ok in ("scene_004", "Büro 3", "a.b-c", "x" * 120):
        assert id_problem(ok) is None, ok
    for bad, words in (("a\nb", "printable"), ("a\tb", "printable"), ("a/b", "separator"),
                       ("..", "separator"), ("", "empty"), (" a", "whitespace"),
                       ("x" * 121, "at most 120")):
        assert words in id_problem(bad), bad


def test_a_second_run_exporting_to_the_same_folder_is_refused_naming_the_first(one_scene,
                                                                                 tmp_path):
    """Issue #33, probe 7: two runs sharing one --export-openpcdet folder no longer both write
    it (the last writer won while the first reported its frames): while one holds the folder,
    another is refused before any work, naming it; afterwards the folder is free again."""
    from sim2radar.datasets import OpenPCDetDataset
    from sim2radar.fileio import FolderBusyError, writer_lock

    export = tmp_path / "opcd"
    args = ["--no-prefect", "--frames", "1", "--no-png", "--out", str(tmp_path / "store"),
            "--export-openpcdet", str(export)]
    with writer_lock(export, "export folder"):
        with pytest.raises(FolderBusyError, match=r"another run is writing this export folder "
                                                  rf"\(pid {os.getpid()} on "):
            with writer_lock(export, "export folder"):
                pass
        for run in (["generate", "--captures", str(one_scene)],
                    ["generate", "--worlds", "1", "--geometry", "ground_truth"]):
            res = CliRunner().invoke(app, [*run, *args], env={"COLUMNS": "400"})
            assert res.exit_code == 2, res.output
            assert "another run is writing this export folder" in res.output
            assert f"pid {os.getpid()}" in res.output
    assert not (tmp_path / "store" / "manifests").exists()
    res = CliRunner().invoke(app, ["generate", "--captures", str(one_scene), *args],
                             env={"COLUMNS": "400"})
    assert res.exit_code == 0, res.output
    assert len(OpenPCDetDataset(export).split_ids("train")) == 1


def test_two_generates_on_one_store_make_each_world_once(tmp_path):
    """Issue #33, probe 7: two `generate`s started together on one store computed every world
    twice; with per-world claims one makes it and the other reads it back (the same frames)."""
    import subprocess
    import sys

    args = ["generate", "--worlds", "2", "--frames", "1", "--geometry", "ground_truth",
            "--width", "80", "--height", "60", "--spp", "2", "--no-prefect", "--no-png",
            "--out", str(tmp_path / "store")]
    code = "import sys; from sim2radar.cli import main; sys.argv[0] = 'sim2radar'; main()"
    procs = [subprocess.Popen([sys.executable, "-c", code, *args, "--json",
                               str(tmp_path / f"s{i}.json")], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True) for i in range(2)]
    outs = [p.communicate(timeout=400)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    summaries = [json.loads((tmp_path / f"s{i}.json").read_text()) for i in range(2)]
    computed = sum(s["counts"]["ok"] for s in summaries)
    assert computed == 2, [s["counts"] for s in summaries]
    assert sum(s["counts"]["skipped"] for s in summaries) == 2
    keys = [sorted(f["artifacts"]["dataset_frames/ground_truth"] for o in s["outcomes"]
                   for f in o["parts"]) for s in summaries]
    assert keys[0] == keys[1]
