"""Every command that writes a store checks up front that a local store can be written: one
line naming the path and the fix, exit 2, before any work (no Prefect, no rendering)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from sim2radar.cli import app

COMMANDS = {
    "simulate": (["simulate", "scene.yaml", "--no-prefect", "--out"], "--out"),
    "reference": (["reference", "--worlds", "1", "--frames", "1", "--no-prefect", "--out"],
                  "--out"),
    "worlds generate": (["worlds", "generate", "--worlds", "1", "--frames", "1",
                         "--no-prefect", "--out"], "--out"),
    "sweep": (["sweep", "sim", "real", "--store"], "--store"),
    "demo": (["demo", "--out"], "--out"),
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_unwritable_store_is_one_line_exit_2(command, unwritable_dir):
    args, option = COMMANDS[command]
    store = unwritable_dir / "store"
    res = CliRunner().invoke(app, [*args, str(store)], env={"COLUMNS": "400"})
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {option}: "), res.output
    assert str(store) in lines[0] and "not writable" in lines[0], lines[0]


OUTPUTS = {  # issue #24 probe 4: output folders other than the store, before any work
    "generate --export-openpcdet": (["generate", "--worlds", "1", "--frames", "1",
                                     "--no-prefect", "--export-openpcdet"],
                                    "--export-openpcdet"),
    "generate --png-dir": (["generate", "--worlds", "1", "--frames", "1", "--no-prefect",
                            "--png-dir"], "--png-dir"),
    "reference --export-openpcdet": (["reference", "--worlds", "1", "--frames", "1",
                                      "--no-prefect", "--export-openpcdet"],
                                     "--export-openpcdet"),
    "sweep --out": (["sweep", "sim", "real", "--out"], "--out"),
}


@pytest.mark.parametrize("command", list(OUTPUTS))
def test_unwritable_output_folder_is_one_line_exit_2_before_any_work(command, unwritable_dir,
                                                                     tmp_path):
    args, option = OUTPUTS[command]
    target = unwritable_dir / "export"
    store = tmp_path / "store"
    extra = ["--store" if command.startswith("sweep") else "--out", str(store)]
    res = CliRunner().invoke(app, [*args, str(target), *extra], env={"COLUMNS": "400"})
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {option}: "), res.output
    assert str(target) in lines[0] and "not writable" in lines[0], lines[0]
    assert not store.exists()  # nothing was computed


@pytest.mark.parametrize("option", ["--frames", "--worlds"])
def test_generate_zero_frames_or_worlds_names_the_option(option, tmp_path):
    res = CliRunner().invoke(app, ["generate", option, "0", "--no-prefect", "--out",
                                   str(tmp_path / "store")], env={"COLUMNS": "400"})
    text = res.output.strip()
    assert res.exit_code == 2 and text.startswith(f"error: {option} must be between 1 and ")
    assert text.endswith(", got 0")
    assert not (tmp_path / "store").exists()
