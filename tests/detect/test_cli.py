"""`sim2radar train` / `sim2radar evaluate` from a YAML config on a dataset on disk."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from sim2radar.cli import app


def test_train_then_evaluate_from_config(tmp_path):
    runner = CliRunner()
    data = tmp_path / "data"
    r = runner.invoke(app, ["detect-demo-data", str(data), "--n-train", "4", "--n-val", "1",
                            "--n-test", "2"])
    assert r.exit_code == 0, r.output
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(
        "data: {root: data}\n"
        "model: {voxel_size_m: [0.1, 0.1, 4.0], layer_nums: [1, 1, 1], "
        "num_filters: [32, 64, 64], num_upsample_filters: [32, 32, 32]}\n"
        "optimization: {batch_size: 2, epochs: 1}\n"
        "runtime: {device: cpu, progress: false}\n"
    )
    r = runner.invoke(app, ["train", str(cfg), "--out", str(tmp_path / "run")])
    assert r.exit_code == 0, r.output
    assert "trained 1 epochs (2 steps)" in r.output
    out = tmp_path / "ap.json"
    r = runner.invoke(app, ["evaluate", str(tmp_path / "run" / "last.pt"), "--split", "test",
                            "--json", str(out)])
    assert r.exit_code == 0, r.output
    res = json.loads(out.read_text())
    assert res["frames"] == 2 and "3d_r40@0.3" in res
    # transfer through the CLI
    r = runner.invoke(app, ["train", str(cfg), "--out", str(tmp_path / "fine"),
                            "--pretrained-encoder", str(tmp_path / "run" / "last.pt")])
    assert r.exit_code == 0, r.output
    # a wide terminal: Typer's rich error box truncates long paths at 80 columns
    r = runner.invoke(app, ["train", str(tmp_path / "missing.yaml")], env={"COLUMNS": "400"})
    assert r.exit_code == 2 and "detector config not found" in r.output, r.output


def test_train_on_a_malformed_label_is_one_line_and_leaves_no_run(tmp_path):
    runner = CliRunner()
    data = tmp_path / "data"
    r = runner.invoke(app, ["detect-demo-data", str(data), "--n-train", "2", "--n-val", "1",
                            "--n-test", "1"])
    assert r.exit_code == 0, r.output
    label = data / "labels" / "000000.txt"
    label.write_text(label.read_text() + "1 2 3 door\n")
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("data: {root: data}\nruntime: {device: cpu, progress: false}\n")
    r = runner.invoke(app, ["train", str(cfg), "--out", str(tmp_path / "run")],
                      env={"COLUMNS": "400"})
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.output, r.output
    assert f"error: {label}:" in lines[0] and "expected 8 fields" in lines[0], lines[0]
    assert not (tmp_path / "run").exists()


def test_detect_demo_data_declares_its_own_domain(tmp_path):
    """Its frames are synthetic: a sweep must not read them as measured radar (a folder
    without a declared domain reads as "undeclared", never "measured")."""
    from sim2radar.datasets import read_metadata
    from sim2radar.experiment.data import open_domain
    from sim2radar.experiment.report import domain_kind

    data = tmp_path / "data"
    r = CliRunner().invoke(app, ["detect-demo-data", str(data), "--n-train", "2", "--n-val",
                                 "1", "--n-test", "1", "--seed", "4"])
    assert r.exit_code == 0, r.output
    meta = read_metadata(data)
    assert meta["domain"] == "synthetic (detect-demo-data)" and meta["seed"] == 4
    assert meta["splits"] == {"train": 2, "val": 1, "test": 1}
    ds = open_domain(data, "real")
    assert ds.domain == "synthetic (detect-demo-data)" and not ds.is_proxy
    assert domain_kind(ds.domain, ds.is_proxy) == "declared"     # reported as not measured
