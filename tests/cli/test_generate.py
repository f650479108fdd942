"""`sim2radar generate`: a bad value in a generate YAML is one line naming the file, the field
and the fix (exit 2), never a traceback or a silently truncated number."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.cli.generate import load_generate_config


@pytest.mark.parametrize("line, field", [
    ("worlds: [1]", "worlds"),       # was a TypeError traceback
    ("worlds: two", "worlds"),       # was "invalid literal for int()", no file, no field
    ("frames: 2.5", "frames"),       # was silently truncated to 2
    ("first_seed: true", "first_seed"),
    ("seed: '3'", "seed"),
    ("worlds: 0", "worlds"),
])
def test_bad_whole_numbers_name_file_and_field(tmp_path, line, field):
    cfg = tmp_path / "gen.yaml"
    cfg.write_text(line + "\n")
    res = CliRunner().invoke(app, ["generate", "--config", str(cfg), "--no-prefect",
                                   "--out", str(tmp_path / "store")], env={"COLUMNS": "400"})
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    assert f"gen.yaml: {field}:" in lines[0], lines[0]
    assert f"write e.g. '{field}: " in lines[0] or "must be >= 1" in lines[0], lines[0]  # the fix
    assert not (tmp_path / "store").exists()  # nothing ran


def test_whole_floats_are_accepted(tmp_path):
    cfg = tmp_path / "gen.yaml"
    cfg.write_text("worlds: 2.0\nframes: 3\n")
    doc = load_generate_config(cfg)
    assert doc["worlds"] == 2 and isinstance(doc["worlds"], int) and doc["frames"] == 3


def test_unwritable_store_fails_up_front(tmp_path, unwritable_dir):
    """A read-only store is one line naming it (exit 2) before any world is rendered, not a
    run that retries every manifest write and dies with tracebacks."""
    (tmp_path / "a_file").write_text("x")
    for out, expect in ((unwritable_dir / "store", "not writable"),
                        (tmp_path / "a_file" / "store", "is a file, not a folder")):
        res = CliRunner().invoke(app, ["generate", "--out", str(out), "--no-prefect",
                                       "--worlds", "1", "--frames", "1", "--width", "80",
                                       "--height", "60", "--spp", "1", "--no-png"],
                                 env={"COLUMNS": "400"})
        assert res.exit_code == 2, res.output
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: --out: "), res.output
        assert str(out) in lines[0] and expect in lines[0], lines[0]


@pytest.mark.parametrize("command", [["generate"], ["reference"], ["simulate", "scene.yaml"]])
@pytest.mark.parametrize("engine", [["--workers", "2"], ["--dask", "local"]])
def test_the_plain_loop_refuses_workers_and_dask(tmp_path, command, engine):
    # --no-prefect runs one unit at a time in this process: it used to drop --workers (and
    # simulate's --dask) without a word
    store = tmp_path / "store"
    res = CliRunner().invoke(app, [*command, "--no-prefect", *engine, "--out", str(store)],
                             env={"COLUMNS": "400"})
    assert res.exit_code == 2, res.output
    line = res.output.strip()
    assert line.startswith(f"error: {' '.join(engine) if engine[0] == '--workers' else '--dask'}"
                           " needs the Prefect engine"), line
    assert "drop --no-prefect" in line and "\n" not in line
    assert not store.exists()                    # refused before any work
