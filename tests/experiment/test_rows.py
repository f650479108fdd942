"""The experiment_runs row is declared once (sim2radar/experiment/rows.py): the store's schema and
the dashboard's check of runs.parquet are derived from it and agree with it."""

from __future__ import annotations

import ast
from pathlib import Path

import pyarrow as pa
import pytest

from sim2radar.experiment.dashboard.reading import RUNS_COLUMNS, _holds
from sim2radar.experiment.rows import RUN_COLUMNS, Column
from sim2radar.storage import get_schema

ROOT = Path(__file__).resolve().parents[2]


def test_the_store_schema_is_the_declared_row():
    schema = get_schema("experiment_runs").schema
    assert schema.names == [c.name for c in RUN_COLUMNS]
    for c in RUN_COLUMNS:
        f = schema.field(c.name)
        assert f.type == c.arrow_type() and f.nullable == c.nullable, c.name
        meta = {k.decode(): v.decode() for k, v in (f.metadata or {}).items()}
        assert meta.get("doc") == c.doc and meta.get("unit", "") == c.unit, c.name
    # what the runs table looks like on disk: a float AP may be null, a status may not
    ap = schema.field("ap_3d_r40_iou03")
    assert ap.type == pa.float64() and ap.nullable
    assert not schema.field("status").nullable


def test_the_dashboard_checks_every_declared_column_by_its_kind():
    schema = get_schema("experiment_runs").schema
    assert RUNS_COLUMNS == {c.name: c.kind for c in RUN_COLUMNS}
    for name, kind in RUNS_COLUMNS.items():
        assert _holds(schema.field(name).type, kind), (name, kind)
    assert Column("x", "list<int32>", "").kind == "integers"
    with pytest.raises(ValueError, match="type 'int8'"):
        Column("x", "int8", "")


def _string_constants(path: Path) -> set[str]:
    return {n.value for n in ast.walk(ast.parse(path.read_text()))
            if isinstance(n, ast.Constant) and isinstance(n.value, str)}


@pytest.mark.parametrize("path", ["storage/schemas.py",
                                  "sim2radar/experiment/dashboard/reading.py"])
def test_no_other_module_declares_a_column_of_the_row(path):
    """A column of experiment_runs spelled in the store's schemas or the dashboard's reader
    would be a second declaration (it was: a pyarrow schema and RUNS_COLUMNS with its own
    types). Allowed: names that are also experiment_pretrain's columns (declared there) and the
    identity columns the dashboard requires non-null."""
    from sim2radar.experiment.dashboard.reading import _RUN_IDENTITY

    allowed = set(get_schema("experiment_pretrain").schema.names) | set(_RUN_IDENTITY)
    spelled = _string_constants(ROOT / path) & {c.name for c in RUN_COLUMNS}
    assert not spelled - allowed, sorted(spelled - allowed)
    assert {"run_key", "history_val_ap", "ap_bev_r11_iou05"} - allowed   # what it would catch
