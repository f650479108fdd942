"""Experiment profiles: the bundled ones load with the intended protocol; paths resolve against
the YAML's folder; bad fields are named with their file."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from sim2radar.experiment.profiles import (
    ABLATIONS,
    CONDITIONS,
    ExperimentProfile,
    bundled_profiles,
    load_profile,
)

REPO = Path(__file__).resolve().parents[2]
PROFILE_DIR = Path(__file__).resolve().parents[2] / "configs" / "experiment"
DETECT_DIR = PROFILE_DIR.parent / "detect"


def test_paper_profile_is_the_papers_protocol():
    p = load_profile("paper")
    assert p.name == "paper" and p.detector == (DETECT_DIR / "pointpillars_door.yaml").resolve()
    assert (p.pretrain_epochs, p.finetune_epochs, p.batch_size, p.lr) == (20, 200, 8, 0.003)
    assert p.fractions == (0.05, 0.10, 0.25, 0.50, 1.00) and p.trials == 5
    assert p.conditions == ("baseline", "sim-pretrain") and p.ablations == ()
    assert p.min_steps is None and p.eval_split == "test" and p.intensity_matching
    cfg = p.detector_config("finetune")
    assert cfg.model.grid_size[:2] == (128, 208) and cfg.model.layer_nums == (3, 5, 5)
    assert cfg.model.voxel_size_m == (0.05, 0.05, 4.0)
    assert (cfg.optimization.epochs, cfg.optimization.batch_size, cfg.optimization.lr) == (
        200, 8, 0.003)
    assert p.detector_config("pretrain").optimization.epochs == 20


def test_demo_and_smoke_profiles():
    demo = load_profile("demo")
    assert demo.detector.name == "pointpillars_door_cpu_small.yaml"
    assert demo.trials >= 3 and demo.fractions == (0.05, 0.10, 0.25, 0.50, 1.00)
    assert demo.min_steps is not None
    smoke = load_profile("smoke")
    cfg = smoke.detector_config()
    assert cfg.model.voxel_size_m[:2] == (0.2, 0.2) and cfg.model.layer_nums == (1,)
    assert max(smoke.pretrain_epochs, smoke.finetune_epochs) <= 2
    assert len(smoke.fractions) == 2 and smoke.trials == 2
    assert cfg.runtime.num_threads == 1 and not cfg.runtime.progress
    # a tiny model: well under a tenth of the CPU model's weights
    from sim2radar.detect import PointPillars

    n = sum(t.numel() for t in PointPillars(cfg.model).parameters())
    n_small = sum(t.numel() for t in PointPillars(demo.detector_config().model).parameters())
    assert n < n_small / 10
    assert set(bundled_profiles()) >= {"paper", "demo", "smoke"}


def test_study_profile_is_the_papers_protocol_on_a_small_model_with_its_design_record():
    """The study keeps the paper's protocol (only the detector is smaller) and records the
    pilots it was designed from before any sim-pretrain run (issue #22)."""
    study, paper = load_profile("study"), load_profile("paper")
    same = ("pretrain_epochs", "finetune_epochs", "batch_size", "lr", "fractions", "trials",
            "conditions", "min_steps", "eval_split", "intensity_matching", "pretrain_per_trial")
    assert {k: getattr(study, k) for k in same} == {k: getattr(paper, k) for k in same}
    cfg = study.detector_config("finetune")
    assert cfg.model.voxel_size_m[:2] == (0.2, 0.2) and cfg.model.num_filters == (32, 64)
    header = (PROFILE_DIR / "study.yaml").read_text().split("description:")[0]
    assert "DESIGN RECORD" in header and "PENDING" not in header
    assert "Decision:" in header and "MDE" in header and "sd" in header


def test_diagnosis_profile_is_the_studys_protocol_preregistered_with_every_arm():
    """The diagnosis (issue #30) keeps the study's protocol and model, runs the low-data
    fractions with the positive control, the ladder and the fine-tuning variant, and points at
    its pre-registration in the repository."""
    diag, study = load_profile("diagnosis"), load_profile("study")
    same = ("pretrain_epochs", "finetune_epochs", "batch_size", "lr", "min_steps",
            "eval_split", "intensity_matching", "pretrain_per_trial", "detector_overrides")
    assert {k: getattr(diag, k) for k in same} == {k: getattr(study, k) for k in same}
    assert diag.fractions == diag.primary == (0.05, 0.10, 0.25)
    assert set(diag.all_conditions) == {"baseline", "sim-pretrain", "sim-gt-pretrain",
                                        "ref-pretrain", "sim-pretrain-lowlr"}
    assert diag.primary_condition == "sim-pretrain" and diag.preregistered
    assert diag.preregistration == REPO / "docs" / "results" / "diagnosis" / "preregistration.md"
    text = diag.preregistration.read_text()
    for part in ("## Question", "## Conditions", "## Trials", "## Endpoints",
                 "## Decision rules", "What would count as transfer"):
        assert part in text
    assert set(diag.learnability_thresholds) == {c for c in diag.all_conditions
                                                 if c != "baseline"}


def _write(tmp_path: Path, name: str = "mine.yaml", **fields) -> Path:
    shutil.copy(DETECT_DIR / "pointpillars_door_cpu_small.yaml", tmp_path / "det.yaml")
    doc = {"detector": "det.yaml", **fields}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc))
    return path


def test_paths_resolve_against_the_yaml_folder(tmp_path, monkeypatch):
    path = _write(tmp_path, trials=3)
    monkeypatch.chdir(PROFILE_DIR)  # a working directory with no det.yaml
    p = load_profile(path)
    assert p.detector == (tmp_path / "det.yaml").resolve() and p.name == "mine"
    assert load_profile(str(path)) == p  # a path as a string


@pytest.mark.parametrize(("fields", "named"), [
    ({"trials": 0}, "'trials'"),
    ({"trails": 5}, "'trails'"),  # typo: extra fields are refused
    ({"fractions": [0.5, 0.25]}, "'fractions'"),
    ({"fractions": [0.0, 0.5]}, "'fractions'"),
    ({"conditions": ["sim-pretrain"]}, "baseline"),
    ({"conditions": ["baseline", "sim-pretrian"]}, "sim-pretrian"),
    ({"conditions": ["baseline", "sim-gt-pretrain"]}, "'ablations'"),
    ({"ablations": ["sim-pretrain"]}, "'ablations'"),
    ({"detector_overrides": {"modle": {}}}, "detector_overrides"),
    ({"detector_overrides": {"model": {"layer_nums": [1, 2]}}}, "detector_overrides"),
    ({"min_steps": 0}, "'min_steps'"),
])
def test_bad_fields_are_named_with_the_file(tmp_path, fields, named):
    path = _write(tmp_path, **fields)
    with pytest.raises(ValueError) as exc:
        load_profile(path)
    msg = str(exc.value)
    assert str(path) in msg and named in msg, msg


def test_unknown_names_list_the_known_ones(tmp_path):
    with pytest.raises(FileNotFoundError, match="paper"):
        load_profile("papr")
    path = tmp_path / "p.yaml"
    path.write_text("detector: nowhere.yaml\n")
    with pytest.raises(FileNotFoundError, match="field 'detector'"):
        load_profile(path)
    with pytest.raises(ValueError, match="sim-gt-pretrain") as exc:
        ExperimentProfile(detector=Path("x.yaml"), conditions=("baseline", "simpretrain"))
    assert "known" in str(exc.value)
    assert set(ABLATIONS) == {"sim-gt-pretrain", "sim-one-material-pretrain"}
    assert CONDITIONS["sim-gt-pretrain"].sim_role == "sim-gt"
    assert CONDITIONS["baseline"].sim_role is None


def test_profile_is_frozen_and_defaults_are_the_papers():
    p = ExperimentProfile(detector=Path("x.yaml"))
    assert (p.pretrain_epochs, p.finetune_epochs, p.trials, p.batch_size) == (20, 200, 5, 8)
    assert p.fractions == (0.05, 0.10, 0.25, 0.50, 1.00)
    assert p.all_conditions == ("baseline", "sim-pretrain")
    with pytest.raises(ValueError):
        p.trials = 3  # frozen


def test_primary_endpoint_thresholds_and_preregistration_fields(tmp_path):
    from sim2radar.experiment.profiles import default_primary_fractions

    paper = load_profile("paper")
    assert paper.primary == (0.05, 0.10, 0.25) and paper.primary_condition == "sim-pretrain"
    assert paper.pretrain_holdout_split == "val" and not paper.preregistered
    assert default_primary_fractions([0.5, 1.0]) == (0.5,)       # none <= 25 %: the smallest
    base = {"detector": "x.yaml", "fractions": [0.1, 0.5, 1.0]}
    assert ExperimentProfile(**base, primary_fractions=[0.5, 1.0]).primary == (0.5, 1.0)
    with pytest.raises(ValueError, match=r"primary_fractions \[0.25\] are not among"):
        ExperimentProfile(**base, primary_fractions=[0.25])
    with pytest.raises(ValueError, match="'nope' is no pre-trained condition"):
        ExperimentProfile(**base, learnability_thresholds={"nope": 5})
    with pytest.raises(ValueError, match="baseline.*is no pre-trained condition"):
        ExperimentProfile(**base, learnability_thresholds={"baseline": 5})
    with pytest.raises(ValueError, match="AP in"):
        ExperimentProfile(**base, learnability_thresholds={"sim-pretrain": 120})
    with pytest.raises(ValueError, match="preregistered: true needs 'preregistration'"):
        ExperimentProfile(**base, preregistered=True)
    # the pre-registration's path resolves against the YAML's folder
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "p.yaml").write_text(
        "detector: ../det.yaml\npreregistered: true\npreregistration: ../pre.md\n")
    (tmp_path / "det.yaml").write_text((Path(paper.detector)).read_text())
    prof = load_profile(tmp_path / "sub" / "p.yaml")
    assert prof.preregistration == (tmp_path / "pre.md").resolve()
