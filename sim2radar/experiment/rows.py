"""The ``experiment_runs`` row, declared once: one fine-tuning run of the sweep's grid.

:data:`RUN_COLUMNS` is the row's only declaration. The store's Parquet schema
(``storage/schemas.py``: :func:`Column.arrow_type`, with ``unit`` and ``doc`` as field metadata)
and the dashboard's check of ``runs.parquet`` (:data:`~.dashboard.reading.RUNS_COLUMNS`:
:attr:`Column.kind`) are both derived from it; ``tests/experiment/test_rows.py`` checks they
agree and that neither spells a column of its own.

    [c.name for c in RUN_COLUMNS]        # sweep, run_key, condition, fraction, ...
    RUN_COLUMNS_BY_NAME["fraction"].kind   # "number"
"""

from __future__ import annotations

import dataclasses
from typing import Any

__all__ = ["Column", "RUN_COLUMNS", "RUN_COLUMNS_BY_NAME", "TYPES"]

#: a column's value type -> what the dashboard calls its values (lists: the plural)
TYPES = {"string": "text", "int32": "integer", "int64": "integer", "float64": "number",
         "list<string>": "texts", "list<int32>": "integers", "list<float64>": "numbers"}


@dataclasses.dataclass(frozen=True)
class Column:
    """One column of a declared row.

    Attributes
    ----------
    name : str — the column name (units in the name's suffix: ``wall_time_s``).
    type : str — one of :data:`TYPES`: ``string``, ``int32``, ``int64``, ``float64`` or a
        ``list<...>`` of them.
    doc : str — what it holds (the Parquet field's ``doc`` metadata).
    unit : str — its unit (``%``, ``s``; the field's ``unit`` metadata), '' for none.
    nullable : bool — whether a row may hold null (e.g. the APs of a failed run).
    """

    name: str
    type: str
    doc: str
    unit: str = ""
    nullable: bool = False

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"column {self.name!r}: type {self.type!r}, expected one of "
                             f"{sorted(TYPES)}")

    @property
    def kind(self) -> str:
        """The kind of value it holds: ``text``, ``integer``, ``number`` (or a list of them:
        ``texts``, ``integers``, ``numbers``)."""
        return TYPES[self.type]

    def arrow_type(self) -> Any:
        """Its ``pyarrow`` type (``pa.int32()``, ``pa.list_(pa.float64())``)."""
        import pyarrow as pa

        scalar = {"string": pa.string, "int32": pa.int32, "int64": pa.int64,
                  "float64": pa.float64}
        if self.type.startswith("list<"):
            return pa.list_(scalar[self.type[5:-1]]())
        return scalar[self.type]()


def _ap_columns() -> tuple[Column, ...]:
    return tuple(
        Column(f"ap_{metric}_r{points}_iou{iou}", "float64",
               f"KITTI-protocol {metric.upper()} AP, R{points}, IoU 0.{iou[1]} on the test split "
               "(null when the run failed)", unit="%", nullable=True)
        for iou in ("03", "05") for metric in ("3d", "bev") for points in (11, 40))


#: the ``experiment_runs`` row: one fine-tuning run (condition x fraction x trial) — its
#: test-split APs, learning curves, timing and outcome
RUN_COLUMNS: tuple[Column, ...] = (
    Column("sweep", "string", "sweep name"),
    Column("run_key", "string", "content key of the run (its identity)"),
    Column("condition", "string",
           "baseline | sim-pretrain | sim-gt-pretrain | sim-one-material-pretrain"),
    Column("fraction", "float64", "share of the real train split, in (0, 1]"),
    Column("n_real_frames", "int32", "real train frames the run saw"),
    Column("n_sim_frames", "int32", "sim frames of its pre-training (0: none)"),
    Column("sim_real_ratio", "float64", "n_sim_frames / n_real_frames (null for baseline)",
           nullable=True),
    Column("trial", "int32", "trial index 0..trials-1"),
    Column("seed", "int64", "trial seed: real subset, head init, shuffling"),
    *_ap_columns(),
    Column("epochs", "int32", "fine-tuning epochs"),
    Column("steps", "int32", "optimiser steps"),
    Column("history_epoch", "list<int32>", "(E,) epoch numbers"),
    Column("history_loss", "list<float64>", "(E,) mean training loss"),
    Column("history_val_epoch", "list<int32>", "(V,) epochs with a val AP"),
    Column("history_val_ap", "list<float64>", "(V,) 3D AP R40 IoU 0.3 on the val split",
           unit="%"),
    Column("wall_time_s", "float64", "training + evaluation wall time", unit="s"),
    Column("device", "string", "torch device"),
    Column("checkpoint", "string", "final checkpoint, relative to the sweep folder"),
    Column("pretrain_key", "string", "content key of the pre-training run (null for baseline)",
           nullable=True),
    Column("status", "string", "ok | failed | skipped"),
    Column("error", "string", "failure reason, empty when ok"),
    Column("finished_at", "string", "UTC ISO-8601 time the run finished"),
)
#: :data:`RUN_COLUMNS` by name
RUN_COLUMNS_BY_NAME = {c.name: c for c in RUN_COLUMNS}
