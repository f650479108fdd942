"""Each run's own view (sim2radar/experiment/dashboard/runs.py): its settings, its learning
curve, its final APs beside its cell, its paired difference to the baseline, its
pre-training's check (found by pretrain_key, or by condition and trial in an older
runs.parquet) and its folder; the live server's ``/run/<id>``.
"""

from __future__ import annotations

import json

import pyarrow.parquet as pq
import pytest

from sim2radar.experiment.dashboard import dashboard_data, load_sweep, serve_dashboard
from sim2radar.experiment.dashboard.runs import run_ids
from tests.experiment.test_dashboard import (
    _get,
    edit_sweep_json,
    make_sweep,
    pretrain_row,
    run_row,
    write_pretrainings,
    write_runs,
)


def _with_pretrainings(folder):
    """A constructed sweep whose sim-pretrain runs load pre-trainings pre-0..2 (their
    pretrain_key, as the sweep flow writes it), with a threshold of 35 held-out AP; trial 1's
    pre-training reaches 40, the others 30."""
    make_sweep(folder)
    edit_sweep_json(folder, learnability_thresholds={"sim-pretrain": 35.0})
    rows = []
    for t in range(3):
        row = pretrain_row(t, heldout=40.0 if t == 1 else 30.0, loss=(3.0, 2.0, 1.0 + t))
        rows.append({**row, "pretrain_key": f"pre-{t}"})    # run_row's pretrain_key
    write_pretrainings(folder, rows)
    return folder


def _view(data: dict, condition: str, fraction: float, trial: int) -> dict:
    return data["run_views"]["views"][f"{condition}-{fraction:g}-{trial}-" + "0" * 40]


def test_every_run_has_a_view_keyed_by_its_run_key(tmp_path):
    folder = _with_pretrainings(tmp_path / "t")
    data = dashboard_data(load_sweep(folder))
    runs = pq.read_table(folder / "runs.parquet").to_pylist()
    assert data["runs"]["ids"] == [r["run_key"] for r in runs]
    assert list(data["run_views"]["views"]) == data["runs"]["ids"]
    # one layout for every run's figure; the views hold their traces only
    assert data["run_views"]["layout"]["xaxis3"]["title"]["text"] == "epoch"
    json.dumps(data, allow_nan=False)


def test_a_runs_view_shows_its_settings_curve_aps_and_difference(tmp_path):
    folder = _with_pretrainings(tmp_path / "t")
    data = dashboard_data(load_sweep(folder))
    v = _view(data, "sim-pretrain", 0.5, 1)
    row = run_row("sim-pretrain", 0.5, 1)
    settings = dict(v["settings"])
    assert settings["seed"] == "1001" and settings["trial"] == "1"
    assert settings["real data"] == "50 % of the train split"
    assert settings["optimiser steps"] == "40 (10 per epoch)"
    assert v["title"] == "Sim Pretrain · 50 % real · trial 1" and v["status"] == "ok"
    # the final APs: the sweep's metric first, each beside its cell's mean over finished runs
    assert v["aps"]["values"]["ap_3d_r40_iou03"] == pytest.approx(row["ap_3d_r40_iou03"])
    first = v["aps"]["rows"][0]
    assert first[0].endswith("(the sweep's metric)") and first[1] == f"{row['ap_3d_r40_iou03']:.2f}"
    # sim-pretrain at 50 %: trial 2 failed, so the cell is trials 0 and 1 (43.0, 44.5)
    assert first[2] == "43.75 ± 1.06 (2 runs)"
    # its paired difference: 3 + 0.5 trial = +3.50 (the cell's mean over 2 pairs +3.25)
    assert v["delta"].startswith("Δ to Baseline of trial 1 at 50 %: +3.50 AP points")
    assert "+3.25 over 2 pair(s)" in v["delta"]
    # the learning curve: its losses per epoch, its val APs, its test AP at the last epoch
    traces = {t["meta"]["role"]: t for t in v["traces"]}
    assert traces["run_loss"]["x"] == row["history_epoch"]
    assert traces["run_loss"]["y"] == pytest.approx(row["history_loss"])
    assert traces["run_val_ap"]["y"] == pytest.approx(row["history_val_ap"])
    assert traces["run_test_ap"]["x"] == [4]
    assert traces["run_test_ap"]["y"] == pytest.approx([row["ap_3d_r40_iou03"]])
    assert v["folder"] == "runs/sim-pretrain-0.5-1"
    assert v["folder_path"] == str(folder / "runs/sim-pretrain-0.5-1")


def test_a_runs_view_shows_the_check_of_the_pretraining_it_loaded(tmp_path):
    folder = _with_pretrainings(tmp_path / "t")
    data = dashboard_data(load_sweep(folder))
    v = _view(data, "sim-pretrain", 0.1, 1)
    pre = v["pretraining"]
    assert pre["id"] == "pretrain-sim-t1" and pre["how"] == "by its pre-training key"
    rows = dict(pre["rows"])
    assert rows["held-out sim AP"].startswith("40.00") and rows["zero-shot real AP"].startswith(
        "5.00")
    assert rows["learnability threshold (held-out)"] == "35 — met"
    assert rows["final loss"] == "2.0000"                    # its loss curve (3, 2, 1 + 1)
    loss = next(t for t in v["traces"] if t["meta"]["role"] == "run_pretrain_loss")
    assert loss["y"] == [3.0, 2.0, 2.0] and loss["xaxis"] == "x3"
    other = dict(_view(data, "sim-pretrain", 0.1, 0)["pretraining"]["rows"])
    assert other["learnability threshold (held-out)"] == "35 — not met"
    # the baseline trains from scratch: no pre-training, no third curve, and the view says so
    base = _view(data, "baseline", 0.1, 0)
    assert base["pretraining"] is None and "from scratch" in base["pretraining_note"]
    assert base["delta"] is None
    assert "run_pretrain_loss" not in {t["meta"]["role"] for t in base["traces"]}


def test_a_failed_run_and_an_older_runs_parquet_without_pretrain_keys(tmp_path):
    folder = _with_pretrainings(tmp_path / "t")
    rows = pq.read_table(folder / "runs.parquet").to_pylist()
    write_runs(folder, [{**r, "pretrain_key": None} for r in rows])
    data = dashboard_data(load_sweep(folder))
    # the one pre-training of the condition and trial, and the view says how it was found
    pre = _view(data, "sim-pretrain", 1.0, 2)["pretraining"]
    assert pre["id"] == "pretrain-sim-t2" and "condition and trial" in pre["how"]
    failed = _view(data, "sim-pretrain", 0.5, 2)
    assert failed["status"] == "failed" and "diverged" in failed["error"]
    assert failed["aps"]["values"]["ap_3d_r40_iou03"] is None
    assert failed["aps"]["rows"][0][1] == "—" and failed["curve_note"]
    assert failed["delta"].startswith("no paired difference")


def test_run_ids_are_run_keys_and_unique():
    rows = [run_row("baseline", 0.1, 0), run_row("baseline", 0.1, 0),
            {**run_row("baseline", 0.5, 1), "run_key": None}]
    key = rows[0]["run_key"]
    assert run_ids(rows) == [key, f"{key}~2", "baseline-0.5-t1"]


def test_server_serves_a_runs_view_at_its_address_and_404_for_an_unknown_run(tmp_path):
    folder = make_sweep(tmp_path / "t")
    key = run_row("baseline", 0.5, 2)["run_key"]
    with serve_dashboard(folder, poll_s=0.5) as server:
        status, page = _get(server.url + f"run/{key}")
        assert status == 200 and b'"data_url":"/data.json"' in page
        assert page == _get(server.url)[1]            # the page opens the run its address names
        status, body = _get(server.url + "run/no-such-run")
        assert status == 404 and b"no run 'no-such-run'" in body
        assert _get(server.url + "run/")[0] == 404
