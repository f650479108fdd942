"""The sweep folder's layout lives in one class (issue #32): no other module spells its file
names, so moving or renaming one is a one-line change."""

from __future__ import annotations

import ast
from pathlib import Path

from sim2radar.experiment.folder import SweepFolder

ROOT = Path(__file__).resolve().parents[2]
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
    assert folder.read_sweep() is None
    folder.root.mkdir()
    folder.update_sweep(packing={"runs": 2})
    folder.update_sweep(precision={"finetune": {"amp": False}})
    assert folder.read_sweep() == {"packing": {"runs": 2},
                                   "precision": {"finetune": {"amp": False}}}
    folder.sweep_json.write_text("{oops")
    import pytest

    with pytest.raises(ValueError, match=r"sweep\.json: unreadable .*new sweep name"):
        folder.read_sweep()
    with pytest.raises(ValueError, match="kind must be"):
        folder.job_dir("other", "k")
    assert set(SweepFolder.PUBLISHED) <= set(SweepFolder.DOCUMENTS)
