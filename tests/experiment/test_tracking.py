"""A sweep folder mirrored into MLflow (sim2radar/experiment/tracking.py), read back with the
MlflowClient from a local ``sqlite:///`` store (MLflow 3's local store; its file store is
refused): one MLflow run per fine-tuning run and per pre-training under the sweep's parent run,
with the row's params, learning curves (step = epoch) and test APs; logging twice adds nothing
and a resumed sweep logs only its new runs; a changed or half-logged run is replaced; a
tracker that cannot be reached warns once; without MLflow the error names the extra.

The sweep folders are the dashboard tests' constructed ones (no training).
"""

from __future__ import annotations

import json
import socket
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from mlflow import MlflowClient

from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.plan import RunSpec
from sim2radar.experiment.stats import sweep_statistics
from sim2radar.experiment.tracking import (
    MlflowMissing,
    SweepTracker,
    TrackingError,
    TrackingWarning,
    read_sweep_folder,
    require_mlflow,
)
from sim2radar.fileio import write_json
from tests.experiment.test_dashboard import make_sweep, pretrain_row, write_pretrainings, write_runs

CONDITIONS = ("baseline", "sim-pretrain", "sim-pretrain-lowlr")
FRACTIONS = (0.1, 0.5)
TRIALS = 2
FAILED = ("sim-pretrain", 0.5, 1)
#: the run with a run folder (config.json, history.json, last.pt)
FOLDER_RUN = ("baseline", 0.1, 0)
COMMIT = "0123456789abcdef0123456789abcdef01234567"


def make_tracked_sweep(folder: Path, *, ran=CONDITIONS, failed=(FAILED,)) -> Path:
    """The dashboard tests' sweep folder with three conditions (one with a lower encoder
    learning rate), two pre-trainings, the resolved detector configs and git commit in
    sweep.json, stats.json, and one run folder."""
    make_sweep(folder, conditions=CONDITIONS, fractions=FRACTIONS, trials=TRIALS, failed=failed,
               ran=ran)
    doc = json.loads((folder / "sweep.json").read_text())
    doc["profile"].update(lr=0.003, batch_size=8, finetune_epochs=4,
                          description="the tracking test's sweep")
    optim = {"lr": 0.003, "epochs": 4, "encoder_lr_scale": 1.0}
    doc["provenance"].update(git=COMMIT + "-dirty", configs={
        "finetune": {"model": {"name": "pointpillars", "voxel_size_m": [0.2, 0.2, 4.0]},
                     "optimization": optim},
        "pretrain": {"model": {"name": "pointpillars"}, "optimization": {**optim, "lr": 0.002}}})
    (folder / "sweep.json").write_text(json.dumps(doc))
    write_pretrainings(folder, [pretrain_row(t, conditions=("sim-pretrain", "sim-pretrain-lowlr"))
                                for t in range(TRIALS)])
    cond, frac, trial = FOLDER_RUN
    run_dir = folder / "runs" / f"{cond}-{frac:g}-{trial}"     # the rows' checkpoint folder
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.json").write_text(json.dumps(doc["provenance"]["configs"]["finetune"]))
    (run_dir / "history.json").write_text(json.dumps({"history": [
        {"epoch": e, "total": 2.0 / e, "cls": 1.0 / e, "loc": 0.8 / e, "dir": 0.2 / e,
         "lr": 0.003 * e / 4, "seconds": 3.0} for e in range(1, 5)], "encoder_loaded": False}))
    (run_dir / "last.pt").write_bytes(b"not a real checkpoint")
    write_stats(folder)
    return folder


def write_stats(folder: Path) -> dict:
    """stats.json of the folder's rows, as the end of a sweep writes it."""
    doc = SweepFolder(folder).read_sweep_document()
    stats = sweep_statistics(doc, pq.read_table(folder / "runs.parquet").to_pylist(),
                             pq.read_table(folder / "pretrainings.parquet").to_pylist(),
                             n_resamples=200)
    write_json(folder / "stats.json", stats)
    return stats


def tracker(uri: str, folder: Path, tmp_path: Path, **kw) -> SweepTracker:
    return SweepTracker(uri, folder, artifact_location=str(tmp_path / "artifacts"), **kw)


def mlflow_runs(client: MlflowClient, exp_id: str, kind: str) -> list:
    return list(client.search_runs([exp_id], f"tags.`sim2radar.kind` = '{kind}'",
                                   max_results=1000))


def run_id_of(row: dict) -> str:
    return RunSpec(condition=row["condition"], fraction=row["fraction"], trial=row["trial"],
                   seed=row["seed"], n_real=row["n_real_frames"], pretrain=None,
                   epochs=row["epochs"]).name


@pytest.fixture
def uri(tmp_path):
    return f"sqlite:///{tmp_path / 'mlflow.db'}"


def test_each_run_and_pretraining_is_one_mlflow_run_under_the_sweeps_run(tmp_path, uri):
    folder = make_tracked_sweep(tmp_path / "t")
    res = tracker(uri, folder, tmp_path).sync(final=True)
    rows = pq.read_table(folder / "runs.parquet").to_pylist()
    pre_rows = pq.read_table(folder / "pretrainings.parquet").to_pylist()
    assert len(res.logged) == len(rows) + len(pre_rows) == 14 and res.unchanged == 0
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name("t")              # the sweep's name by default
    assert exp.experiment_id == res.experiment_id
    (parent,) = mlflow_runs(client, exp.experiment_id, "sweep")
    runs = {r.info.run_name: r for r in mlflow_runs(client, exp.experiment_id, "run")}
    pres = {r.info.run_name: r for r in mlflow_runs(client, exp.experiment_id, "pretraining")}
    assert set(runs) == {run_id_of(r) for r in rows} and len(runs) == 12
    assert set(pres) == {r["pretrain_id"] for r in pre_rows}
    for r in [*runs.values(), *pres.values()]:
        assert r.data.tags["mlflow.parentRunId"] == parent.info.run_id == res.parent_run_id
        assert r.data.tags["sim2radar.sweep"] == "t"
        assert r.data.tags["mlflow.source.git.commit"] == COMMIT
        assert r.data.tags["sim2radar.git_commit"] == COMMIT + "-dirty"

    for row in rows:
        run = runs[run_id_of(row)]
        p, m, tags = run.data.params, run.data.metrics, run.data.tags
        assert (p["condition"], float(p["fraction"]), int(p["trial"]), int(p["seed"])) == (
            row["condition"], row["fraction"], row["trial"], row["seed"])
        assert p["dataset.real.path"] == "/data/real" and p["dataset.real.key"] == "r" * 16
        assert tags["sim2radar.key"] == row["run_key"]
        assert tags["sim2radar.condition"] == row["condition"]
        # the learning rates: the lower-lr arm's encoder at 0.1 x lr, the head at lr
        scale = 0.1 if row["condition"] == "sim-pretrain-lowlr" else 1.0
        assert float(p["lr"]) == 0.003 and float(p["encoder_lr_scale"]) == scale
        assert float(p["encoder_lr"]) == pytest.approx(0.003 * scale, rel=1e-12)
        assert p["detector.model.voxel_size_m"] == "[0.2, 0.2, 4.0]"
        assert p["profile.batch_size"] == "8"
        if row["status"] == "failed":
            assert run.info.status == "FAILED"
            assert "diverged" in tags["sim2radar.error"]
            assert not any(k.startswith("ap_") for k in m) and "train_loss" not in m
            continue
        assert run.info.status == "FINISHED"
        # the final APs are runs.parquet's, to the bit
        aps = {k: v for k, v in row.items() if k.startswith("ap_")}
        assert len(aps) == 8 and all(m[k] == v for k, v in aps.items())
        loss = client.get_metric_history(run.info.run_id, "train_loss")
        assert [(h.step, h.value) for h in loss] == list(zip(row["history_epoch"],
                                                             row["history_loss"], strict=True))
        val = client.get_metric_history(run.info.run_id, "val_ap_3d_r40_iou03")
        assert [(h.step, h.value) for h in val] == list(zip(row["history_val_epoch"],
                                                            row["history_val_ap"], strict=True))

    for row in pre_rows:
        run = pres[row["pretrain_id"]]
        m, p = run.data.metrics, run.data.params
        assert m["heldout_ap_3d_r40_iou03"] == row["heldout_ap_3d_r40_iou03"]
        assert m["zero_shot_ap_3d_r40_iou03"] == row["zero_shot_ap_3d_r40_iou03"]
        assert len(client.get_metric_history(run.info.run_id, "train_loss")) == 3
        assert p["sim_role"] == "sim" and float(p["lr"]) == 0.002      # the pre-training's lr
        assert p["conditions"] == "sim-pretrain,sim-pretrain-lowlr"
        assert run.data.tags["sim2radar.key"] == row["pretrain_key"]

    # the parent: the sweep's settings, counts, primary endpoint and files; FAILED (a run did)
    stats = json.loads((folder / "stats.json").read_text())
    (primary,) = [x for x in stats["pooled"] if x["primary"]]
    pm = parent.data.metrics
    assert pm["primary.mean_diff"] == primary["mean_diff"]
    assert (pm["primary.ci_low"], pm["primary.ci_high"]) == tuple(primary["t_ci"])
    assert (pm["runs_finished"], pm["runs_failed"], pm["pretrainings_finished"]) == (11, 1, 2)
    cell = next(c for c in stats["cells"] if c["condition"] == "baseline")
    assert pm[f"mean.baseline.f{cell['fraction']:g}"] == cell["mean"]
    assert parent.info.status == "FAILED"
    assert parent.data.params["profile.lr"] == "0.003"
    assert parent.data.tags["mlflow.note.content"] == "the tracking test's sweep"
    files = {a.path for a in client.list_artifacts(parent.info.run_id)}
    assert {"sweep.json", "stats.json", "runs.parquet", "pretrainings.parquet",
            "progress.json"} <= files


def test_a_runs_small_files_go_along_and_its_checkpoint_only_when_asked(tmp_path, uri):
    folder = make_tracked_sweep(tmp_path / "t")
    tracker(uri, folder, tmp_path).sync()
    client = MlflowClient(tracking_uri=uri)
    exp_id = client.get_experiment_by_name("t").experiment_id
    cond, frac, trial = FOLDER_RUN
    name = f"{cond}-f{frac:g}-t{trial}"
    (run,) = [r for r in mlflow_runs(client, exp_id, "run") if r.info.run_name == name]
    files = {a.path for a in client.list_artifacts(run.info.run_id)}
    assert files == {"row.json", "config.json", "history.json"}      # no last.pt
    assert run.data.tags["sim2radar.run_dir"] == str((folder / "runs" / "baseline-0.1-0")
                                                     .resolve())
    # the loss parts and learning rate per epoch, from the run folder's history.json
    cls = client.get_metric_history(run.info.run_id, "train_loss_cls")
    assert [(h.step, h.value) for h in cls] == [(e, 1.0 / e) for e in range(1, 5)]
    assert [h.step for h in client.get_metric_history(run.info.run_id, "lr")] == [1, 2, 3, 4]
    row = json.loads(Path(client.download_artifacts(run.info.run_id, "row.json",
                                                    str(tmp_path))).read_text())
    assert row["run_key"] == run.data.tags["sim2radar.key"]

    other = f"sqlite:///{tmp_path / 'with-checkpoints.db'}"
    tracker(other, folder, tmp_path, checkpoints=True).sync()
    client = MlflowClient(tracking_uri=other)
    exp_id = client.get_experiment_by_name("t").experiment_id
    (run,) = [r for r in mlflow_runs(client, exp_id, "run") if r.info.run_name == name]
    assert {a.path for a in client.list_artifacts(run.info.run_id, "checkpoints")} == {
        "checkpoints/last.pt"}


def test_logging_twice_adds_nothing_and_a_resumed_sweep_logs_only_its_new_runs(tmp_path, uri):
    folder = make_tracked_sweep(tmp_path / "t", ran=("baseline",), failed=())
    (folder / "stats.json").unlink()                 # a sweep killed after its baseline runs
    first = tracker(uri, folder, tmp_path).sync()
    assert len(first.logged) == 4 + 2
    client = MlflowClient(tracking_uri=uri)
    exp_id = first.experiment_id
    (parent,) = mlflow_runs(client, exp_id, "sweep")
    assert parent.info.status == "RUNNING"
    before = {r.info.run_name: r.info.run_id for r in mlflow_runs(client, exp_id, "run")}

    def history_lengths() -> dict:
        return {(r.info.run_name, k): len(client.get_metric_history(r.info.run_id, k))
                for r in client.search_runs([exp_id], max_results=1000) for k in r.data.metrics}

    lengths = history_lengths()
    again = tracker(uri, folder, tmp_path).sync()       # a new process: found, not relogged
    assert again.logged == () and again.unchanged == 6
    assert again.parent_run_id == parent.info.run_id
    assert history_lengths() == lengths
    assert len(client.search_runs([exp_id], max_results=1000)) == 7

    # the resumed sweep: its finished runs read back as skipped, the others new
    full = make_tracked_sweep(tmp_path / "full")
    rows = pq.read_table(full / "runs.parquet").to_pylist()
    rows = [{**r, "sweep": "t", "status": "skipped"} if r["condition"] == "baseline" else
            {**r, "sweep": "t"} for r in rows]
    write_runs(folder, rows)
    stats = write_stats(folder)
    resumed = tracker(uri, folder, tmp_path).sync(final=True)
    assert sorted(resumed.logged) == sorted(run_id_of(r) for r in rows
                                            if r["condition"] != "baseline")
    assert resumed.replaced == ()
    now = {r.info.run_name: r for r in mlflow_runs(client, exp_id, "run")}
    assert len(now) == 12 and all(now[n].info.run_id == i for n, i in before.items())
    (parent,) = mlflow_runs(client, exp_id, "sweep")
    assert parent.info.status == "FAILED"               # the resumed sweep has a failed run
    (primary,) = [x for x in stats["pooled"] if x["primary"]]
    assert parent.data.metrics["primary.mean_diff"] == primary["mean_diff"]
    lengths = history_lengths()
    assert tracker(uri, folder, tmp_path).sync(final=True).logged == ()
    assert history_lengths() == lengths

    # the failed run retried and finished: its MLflow run is replaced, the old one deleted
    failed = next(r for r in rows if r["status"] == "failed")
    fixed = next(r for r in pq.read_table(full / "runs.parquet").to_pylist()
                 if r["run_key"] == failed["run_key"])
    fixed = {**fixed, "sweep": "t", "status": "ok", "error": "",
             "finished_at": "2026-11-21T10:00:00+00:00"}
    for k in fixed:
        if k.startswith("ap_"):
            fixed[k] = 42.0
    fixed["history_epoch"], fixed["history_loss"] = [1, 2], [1.0, 0.5]
    write_runs(folder, [fixed if r["run_key"] == failed["run_key"] else r for r in rows])
    # ... and a run whose logging was cut off (still RUNNING) is logged again
    cut = now[run_id_of(rows[0])].info.run_id
    client.update_run(cut, "RUNNING")
    res = tracker(uri, folder, tmp_path).sync()
    assert sorted(res.replaced) == sorted([run_id_of(failed), run_id_of(rows[0])])
    old = client.get_run(now[run_id_of(failed)].info.run_id)
    assert old.info.lifecycle_stage == "deleted"
    assert client.get_run(cut).info.lifecycle_stage == "deleted"
    now = {r.info.run_name: r for r in mlflow_runs(client, exp_id, "run")}
    assert len(now) == 12
    new = now[run_id_of(failed)]
    assert new.info.status == "FINISHED" and new.data.metrics["ap_3d_r40_iou03"] == 42.0
    assert now[run_id_of(rows[0])].info.status == "FINISHED"


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_tracker_warns_once_and_the_sweep_goes_on(tmp_path, monkeypatch):
    # MLflow retries a server for ~4 minutes by default; these say: once, quickly
    monkeypatch.setenv("MLFLOW_HTTP_REQUEST_MAX_RETRIES", "0")
    monkeypatch.setenv("MLFLOW_HTTP_REQUEST_TIMEOUT", "2")
    folder = make_tracked_sweep(tmp_path / "t")
    dead = f"http://user:secret@127.0.0.1:{_closed_port()}"
    t = SweepTracker(dead, folder, on_error="warn")
    with pytest.warns(TrackingWarning) as caught:
        first = t.sync()
        second = t.sync(final=True)
    assert len(caught) == 1
    message = str(caught[0].message)
    assert "127.0.0.1" in message and "Connection refused" in message
    assert f"sim2radar sweep-report {folder} --mlflow" in message
    assert "secret" not in message                      # the password is not printed
    assert first.error and second.error == first.error and second.logged == ()
    with pytest.raises(TrackingError, match=r"127\.0\.0\.1.*looking up experiment 't'.*"
                                            r"sweep-report"):
        SweepTracker(dead, folder).sync()


def test_without_mlflow_the_error_names_the_extra(tmp_path, monkeypatch):
    folder = make_tracked_sweep(tmp_path / "t")
    monkeypatch.setitem(sys.modules, "mlflow", None)          # `import mlflow` fails
    with pytest.raises(MlflowMissing, match=r"pip install 'sim2radar\[mlflow\]'"):
        require_mlflow()
    with pytest.raises(ImportError, match=r"pip install 'sim2radar\[mlflow\]'"):
        SweepTracker("sqlite:///x.db", folder)


def test_a_folder_that_cannot_be_logged_names_the_file(tmp_path, uri):
    folder = make_tracked_sweep(tmp_path / "t")
    (folder / "runs.parquet").write_bytes(b"PAR1 not really")
    with pytest.raises(ValueError, match=r"runs\.parquet: cannot be read as Parquet"):
        read_sweep_folder(folder)
    with pytest.warns(TrackingWarning, match=r"runs\.parquet.*sweep-report"):
        assert tracker(uri, folder, tmp_path, on_error="warn").sync().error
    (folder / "sweep.json").unlink()
    with pytest.raises(ValueError, match=r"sweep\.json: not found"):
        tracker(uri, folder, tmp_path).sync()
    # a stats.json that counts other runs than runs.parquet is not logged as the sweep's
    folder = make_tracked_sweep(tmp_path / "u")
    rows = pq.read_table(folder / "runs.parquet").to_pylist()
    write_runs(folder, rows[:-1])
    assert read_sweep_folder(folder).stats is None
