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
