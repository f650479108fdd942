"""`sim2radar config list|show|copy` (issue #34, installed-package polish): a newcomer starts
from a bundled config; a copied experiment profile still finds its detector config."""

from __future__ import annotations

from typer.testing import CliRunner

from sim2radar.cli import app


def test_list_show_and_copy_a_bundled_config_that_works_from_elsewhere(tmp_path):
    from sim2radar.experiment.profiles import load_profile

    runner = CliRunner()
    res = runner.invoke(app, ["config", "list"])
    assert res.exit_code == 0 and "experiment/demo" in res.output and "radar/ti-mmwcas" in res.output
    res = runner.invoke(app, ["config", "show", "generate/default"])
    assert res.exit_code == 0 and "nightly job" in res.output and "rig:" in res.output
    res = runner.invoke(app, ["config", "copy", "experiment/demo", str(tmp_path)])
    assert res.exit_code == 0, res.output
    copy = tmp_path / "demo.yaml"
    profile = load_profile(copy)
    assert profile.detector.is_file() and profile.detector.name.endswith("_cpu_small.yaml")
    res = runner.invoke(app, ["config", "copy", "experiment/demo", str(copy)])
    assert res.exit_code == 2 and "exists" in res.output
    res = runner.invoke(app, ["config", "show", "nope"])
    assert res.exit_code == 2 and "config list" in res.output
    res = runner.invoke(app, ["config", "show", "ti-mmwcas"])   # a bare name of one kind
    assert res.exit_code == 0 and "adc_samples" in res.output


def test_tables_are_not_cut_at_80_columns_when_piped(monkeypatch):
    """Issue #34 polish: piped into a file, Rich assumed 80 columns and cut wide tables."""
    import io
    import sys

    from sim2radar.cli._app import console

    monkeypatch.delenv("COLUMNS", raising=False)
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    assert console().width == 200
    monkeypatch.setenv("COLUMNS", "123")
    assert console().width == 123


def test_bundled_scene_names_resolve_for_simulate(tmp_path, monkeypatch):
    """Issue #34 polish: `simulate demo` found no scene outside the checkout; a bare name of a
    bundled scene resolves to the package's file, a real file or folder still wins."""
    from sim2radar.scenes import DEMO_DIR, expand_scenes

    monkeypatch.chdir(tmp_path)
    assert expand_scenes(["demo"]) == [str(DEMO_DIR / "corridor.yaml")]
    assert expand_scenes(["corridor"]) == [str(DEMO_DIR / "corridor.yaml")]
    (tmp_path / "demo").mkdir()
    (tmp_path / "demo" / "mine.yaml").write_text("meshes: []\n")
    assert expand_scenes(["demo"]) == [str(tmp_path / "demo" / "mine.yaml")] or \
        expand_scenes(["demo"]) == ["demo/mine.yaml"]
    assert expand_scenes(["nothing.yaml"]) == ["nothing.yaml"]   # failed later, by the flow


def test_a_bundled_production_config_looks_for_models_in_the_working_folder(tmp_path,
                                                                              monkeypatch):
    """Issue #34 polish: `models check production` looked for model files inside
    site-packages; a bundled config named without a path resolves its relative model paths
    against the working folder (a YAML path still against its own folder)."""
    from sim2radar.reconstruct import ReconstructionConfig

    monkeypatch.chdir(tmp_path)
    cfg = ReconstructionConfig.from_yaml("production")
    assert cfg.depth.options["model_path"].startswith(str(tmp_path / "models"))
    (tmp_path / "cfg").mkdir()
    (tmp_path / "cfg" / "p.yaml").write_text(
        "depth: {name: moge, options: {model_path: m/d.onnx}}\n")
    cfg = ReconstructionConfig.from_yaml(tmp_path / "cfg" / "p.yaml")
    assert cfg.depth.options["model_path"] == str(tmp_path / "cfg" / "m" / "d.onnx")
