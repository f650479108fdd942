"""The sweep folder's layout lives in one class (issue #32): no other module spells its file
names, so moving or renaming one is a one-line change."""

from __future__ import annotations

import ast
import gzip
import json
from pathlib import Path

import pytest

from sim2radar.experiment.documents import DocumentError, SweepDocument, SweepProgress
from sim2radar.experiment.folder import SweepFolder
from sim2radar.fileio import write_json

ROOT = Path(__file__).resolve().parents[2]
#: the published diagnosis study: a sweep folder written before the documents were typed
DIAGNOSIS = ROOT / "docs" / "results" / "diagnosis"
#: the file names only SweepFolder may spell
NAMES = {SweepFolder.SWEEP, SweepFolder.PLAN, SweepFolder.RUNS, SweepFolder.PRETRAININGS,
         SweepFolder.PROGRESS, SweepFolder.STATS, SweepFolder.RESULTS, SweepFolder.DASHBOARD,
         SweepFolder.PREREGISTRATION, SweepFolder.GENERATION, SweepFolder.GAP_REPORT,
         SweepFolder.CHECK, SweepFolder.DONE}
#: the trainer writes its own run folder's files (a sweep's runs/<key>/ is one)
TRAINER = {"sim2radar/detect/train.py": {"history.json", "last.pt"}}


def test_no_module_but_sweep_folder_spells_a_sweep_file_name():
    offenders = []
    for top in ("sim2radar", "tasks", "flows", "storage"):
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel == "sim2radar/experiment/folder.py":
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                        and node.value in NAMES - TRAINER.get(rel, set()):
                    offenders.append(f"{rel}:{node.lineno}: {node.value!r}")
    assert not offenders, "use SweepFolder instead of spelling these:\n" + "\n".join(offenders)


def test_sweep_folder_paths_and_documents(tmp_path):
    folder = SweepFolder(tmp_path / "s")
    assert folder.sweep_json == tmp_path / "s" / "sweep.json"
    assert folder.run_dir("k") == tmp_path / "s" / "runs" / "k"
    assert folder.pretrain_dir("k") == tmp_path / "s" / "pretrain" / "k"
    assert folder.quarantine_dir("runs", "k", "T") == tmp_path / "s" / "quarantine/runs/k.T"
    assert folder.gap_json.parent == folder.gap_dir
    assert folder.read_sweep_document() is None
    assert folder.read_progress() is None
    with pytest.raises(FileNotFoundError, match=r"sweep\.json: not found; prepare the sweep"):
        folder.update_sweep(packing={"runs": 2})
    folder.root.mkdir()
    folder.sweep_json.write_text("{oops")
    with pytest.raises(DocumentError, match=r"sweep\.json: not valid JSON \(.* at line 1, "
                       r"column 2\); delete it .*new sweep name"):
        folder.read_sweep_document()
    with pytest.raises(ValueError, match="kind must be"):
        folder.job_dir("other", "k")
    assert set(SweepFolder.PUBLISHED) <= set(SweepFolder.DOCUMENTS)


def _sweep_dict(**extra) -> dict:
    """A sweep.json as the sweep writes it (every field, in the order it writes them)."""
    return {"name": "t", "profile": {"name": "smoke", "lr": 0.003, "fractions": [0.1, 0.5]},
            "conditions": ["baseline", "sim-pretrain"], "fractions": [0.1, 0.5], "trials": 2,
            "metric": "ap_3d_r40_iou03",
            "datasets": {"real": {"path": "/r", "domain": "proxy-real", "n_frames": 60}},
            "real_domain": "proxy-real", "real_is_proxy": True,
            "intensity_match": {"sim-t0": {"kind": "quantile", "slope": 1.5e-3}},
            "n_pretrains": 2, "n_runs": 8,
            "provenance": {"versions": {"python": "3.11"}, "code": {"stage_version": 3},
                           "git": "abc-dirty", "configs": {"finetune": {"x": 1}}},
            "settings": {"profile": {"lr": 0.003}}, "settings_digest": "d" * 20,
            "settings_fixed_at": "2026-11-20T08:00:00+00:00",
            "created_at": "2026-11-20T09:00:00+00:00",
            "precision": {"finetune": {"amp": "bfloat16"}}, "preregistration": None, **extra}


def test_the_sweep_document_is_written_as_the_dict_was_and_updated_in_place(tmp_path):
    """sweep.json's bytes are write_json's of the dict the sweep wrote before it was typed
    (keys in the same order, the same indentation); update_sweep replaces a field where it is
    and adds a new one last, as the dict merge did."""
    raw = _sweep_dict()
    old = SweepFolder(tmp_path / "old")
    old.root.mkdir()
    write_json(old.sweep_json, raw)
    new = SweepFolder(tmp_path / "new")
    new.root.mkdir()
    doc = SweepDocument(**raw)
    new.write_sweep_document(doc)
    assert new.sweep_json.read_bytes() == old.sweep_json.read_bytes()
    assert new.read_sweep_document() == doc
    new.update_sweep(packing={"runs": 2, "gpus": 1})
    new.update_sweep(precision={"finetune": {"amp": False}})
    write_json(old.sweep_json, {**raw, "packing": {"runs": 2, "gpus": 1},
                                "precision": {"finetune": {"amp": False}}})
    assert new.sweep_json.read_bytes() == old.sweep_json.read_bytes()
    again = new.read_sweep_document()
    assert again.held("packing") == {"runs": 2, "gpus": 1} and again.precision["finetune"] == {
        "amp": False}
    with pytest.raises(DocumentError, match=r"field 'n_runs' is 'many'"):
        new.update_sweep(n_runs="many")
    assert new.read_sweep_document() == again                 # a refused update writes nothing


def test_progress_is_written_as_the_flow_wrote_it_and_an_old_one_reads(tmp_path):
    """progress.json: the bytes the flow's dict gave; the published study's file (written before
    pre-trainings were counted) reads, lacks what it lacks, and writes back the same bytes."""
    folder = SweepFolder(tmp_path)
    as_dict = {"total_runs": 8, "finished": 3, "failed": 1, "total_pretrainings": 2,
               "pretrainings_finished": 2, "updated_at": "2026-11-27T14:21:21+00:00"}
    write_json(tmp_path / "dict.json", as_dict)
    folder.write_progress(SweepProgress(**as_dict))
    assert folder.progress_json.read_bytes() == (tmp_path / "dict.json").read_bytes()
    assert folder.read_progress() == SweepProgress(**as_dict)
    published = SweepFolder(DIAGNOSIS).read_progress()
    assert (published.total_runs, published.finished, published.failed) == (120, 120, 0)
    assert published.held("total_pretrainings") is None and published.running == []
    folder.write_progress(published)
    assert folder.progress_json.read_bytes() == (DIAGNOSIS / "progress.json").read_bytes()
    folder.progress_json.write_text('{"total_runs": 8, "finished": "three", "failed": 0}')
    with pytest.raises(DocumentError, match=r"progress\.json: field 'finished' is 'three': .*; "
                       "delete it"):
        folder.read_progress()


def test_a_published_sweep_reads_from_its_compressed_copy_and_writes_back_the_same():
    """docs/results/diagnosis keeps sweep.json gzip-compressed (written by the code before the
    documents were typed): it reads as a SweepDocument and writes back byte for byte."""
    folder = SweepFolder(DIAGNOSIS)
    assert not folder.sweep_json.is_file()
    doc = folder.read_sweep_document()
    assert doc.name and doc.n_runs == 120 and doc.held("precision") is None
    text = gzip.decompress(folder.sweep_json.with_name("sweep.json.gz").read_bytes())
    assert (json.dumps(doc.model_dump(mode="json"), indent=1) + "\n").encode() == text


def test_a_sweep_json_from_before_settings_were_recorded_still_loads(tmp_path):
    """A hand-written sweep.json of an early sweep (no settings, precision, pre-trainings or
    pre-registration) loads; the fields it lacks read as absent, and it keeps its bytes."""
    early = {"name": "early", "profile": {"name": "demo"}, "conditions": ["baseline"],
             "fractions": [0.1], "trials": 1, "metric": "ap_3d_r40_iou03",
             "datasets": {}, "real_domain": "undeclared", "n_runs": 1,
             "provenance": {"versions": {}}, "created_at": "2026-10-01T00:00:00+00:00",
             "note": "kept"}
    folder = SweepFolder(tmp_path)
    write_json(folder.sweep_json, early)
    before = folder.sweep_json.read_bytes()
    doc = folder.read_sweep_document()
    assert doc.settings is None and doc.held("n_pretrains") is None and doc.held("note") == "kept"
    folder.write_sweep_document(doc)
    assert folder.sweep_json.read_bytes() == before


@pytest.mark.parametrize("value,problem", [
    ([], r"holds list, not the sweep's document"),
    ({"name": "t", "settings": None}, r"field 'settings' is None, not the settings document "
                                      r"the sweep wrote"),
    ({"name": "t", "settings": "abc"}, r"field 'settings' is 'abc', not the settings document"),
    ({"name": "t", "settings_digest": "d", "created_at": "c"},
     r"it has a settings digest \(d\) but no settings: the file was edited"),
    ({"name": "t", "fractions": [0.1, "a"]}, r"field 'fractions\.1' is 'a': Input should be"),
    ({"fractions": [0.1]}, r"field 'name' is missing"),
])
def test_a_damaged_sweep_json_is_refused_in_one_line(tmp_path, value, problem):
    """Issue #33 probe 6, on the typed read: a sweep.json of [], settings null or a string, or
    one whose settings were deleted (but whose digest remains), or a field of another type, is
    refused in one line naming the file, what is wrong and the fix; never read as a sweep
    without settings (which would skip the changed-settings check)."""
    folder = SweepFolder(tmp_path)
    folder.sweep_json.write_text(json.dumps(value))
    with pytest.raises(DocumentError, match=problem) as info:
        folder.read_sweep_document()
    msg = str(info.value)
    assert msg.startswith(f"{folder.sweep_json}: ") and "\n" not in msg
    assert msg.endswith(SweepFolder.SWEEP_FIX) and info.value.problem in msg
