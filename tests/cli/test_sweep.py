"""``sim2radar sweep``'s dataset options: one per dataset role of the condition registry, mapped
to their roles through it (the sweep itself is tested in tests/flows/test_experiment.py); and
``--mlflow`` on ``sweep`` and ``sweep-report``: each run logged as it finishes, once; a tracker
that is down warns once and the sweep finishes; no MLflow installed fails before any work. The
sweep's flow is replaced here by one that finishes a constructed sweep folder's runs one by one
(tests/experiment/test_dashboard.py's), so no training runs."""

from __future__ import annotations

import socket
import sys
from pathlib import Path
from types import SimpleNamespace

import pyarrow.parquet as pq
import pytest
import typer
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.cli.experiment import sweep_datasets
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.profiles import CONDITIONS


def test_every_conditions_dataset_has_its_option():
    sweep = typer.main.get_command(app).commands["sweep"]
    options = {o for p in sweep.params for o in getattr(p, "opts", ())}
    flags = {c.flag for c in CONDITIONS.values() if c.flag}
    assert "--sim" in flags                                    # SIM, the first argument
    assert flags - {"--sim"} <= options
    given = {f: f"data/{f[2:]}" for f in flags - {"--sim"}}
    assert sweep_datasets("data/s", "data/r", {**given, "--sim-gt": None}) == {
        "sim": "data/s", "real": "data/r",
        **{CONDITIONS[n].sim_role: f"data/{CONDITIONS[n].sim_role}" for n in CONDITIONS
           if CONDITIONS[n].flag not in (None, "--sim", "--sim-gt")}}
    with pytest.raises(ValueError, match="--sim-noisy"):
        sweep_datasets("s", "r", {"--sim-noisy": "n"})


def test_dataset_role_pairs():
    """``--dataset ROLE=PATH`` names any registry role (the shorthands' too)."""
    assert sweep_datasets("s", "r", {}, ["ref=data/ref", "sim-gt = data/gt"]) == {
        "sim": "s", "real": "r", "ref": "data/ref", "sim-gt": "data/gt"}
    for pair, message in (("ref", "expected ROLE=PATH"), ("=x", "expected ROLE=PATH"),
                          ("real=x", "REAL argument"), ("noisy=x", "known roles"),
                          ("ref=", "expected ROLE=PATH")):
        with pytest.raises(ValueError, match=message):
            sweep_datasets("s", "r", {}, [pair])
    with pytest.raises(ValueError, match="given twice"):
        sweep_datasets("s", "r", {"--ref": "a"}, ["ref=b"])


# ------------------------------------------------------------------------------ --mlflow
def _constructed_sweep(folder: Path) -> list[dict]:
    """The dashboard tests' sweep folder (2 conditions x 3 fractions x 3 trials, none failed,
    no pre-training); returns its rows."""
    from tests.experiment.test_dashboard import make_sweep

    make_sweep(folder, failed=())
    return pq.read_table(folder / "runs.parquet").to_pylist()


def _fake_flow(monkeypatch, tmp_path: Path, uri: str | None = None,
               experiment: str | None = None) -> dict:
    """Replace the sweep's preparation and flow: the flow finishes the constructed sweep's runs
    one at a time (runs.parquet rewritten, then the progress callback, as the real flow does)
    and ends with its stats.json. With ``uri``, records after each run how many runs MLflow's
    ``experiment`` holds."""
    import sim2radar.flows._states as states
    import sim2radar.tasks.sweep as sweep_job
    from sim2radar.experiment.stats import sweep_statistics
    from sim2radar.fileio import write_json
    from sim2radar.flows import _progress
    from tests.experiment.test_dashboard import write_runs

    seen = {"mlflow_runs_after_each": []}

    def prepare(request):
        name, folder = request.name, Path(request.out) / request.name
        seen["rows"] = _constructed_sweep(folder)
        write_runs(folder, [])                    # no run finished yet
        return SimpleNamespace(name=name, context=SimpleNamespace(sweep_dir=str(folder)),
                               pretrains=(), runs=seen["rows"], concurrent_runs=1,
                               plan_path=str(folder / "plan.json"))

    def run_flow(flow, request):
        folder, rows = Path(request.plan_path).parent, seen["rows"]
        for i, row in enumerate(rows):
            write_runs(folder, rows[: i + 1])
            _progress.notify("sweep", row)
            if uri is not None:
                from mlflow import MlflowClient

                client = MlflowClient(tracking_uri=uri)
                exp = client.get_experiment_by_name(experiment)
                seen["mlflow_runs_after_each"].append(len(client.search_runs(
                    [exp.experiment_id], "tags.`sim2radar.kind` = 'run'", max_results=1000)))
        doc = SweepFolder(folder).read_sweep_document()
        stats = sweep_statistics(doc, rows, n_resamples=200)
        write_json(folder / "stats.json", stats)
        (folder / "results.md").write_text("# results\n")
        return {"name": folder.name, "sweep_dir": str(folder), "metric": stats["metric"],
                "counts": {"ok": len(rows), "skipped": 0, "failed": 0}, "stats": stats,
                "results_md": str(folder / "results.md"),
                "dashboard": str(folder / "dashboard.html")}

    monkeypatch.setattr(sweep_job, "prepare", prepare)
    monkeypatch.setattr(states, "run_flow", run_flow)
    monkeypatch.chdir(tmp_path)          # a sqlite store keeps its artifacts in ./mlruns
    return seen


def _sweep(tmp_path: Path, *args: str):
    return CliRunner().invoke(app, ["sweep", "sim", "real", "--profile", "smoke", "--name", "t",
                                    "--out", str(tmp_path / "out"), "--store",
                                    str(tmp_path / "store"), *args])


def test_sweep_logs_each_run_to_mlflow_as_it_finishes(tmp_path, monkeypatch):
    from mlflow import MlflowClient

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    seen = _fake_flow(monkeypatch, tmp_path, uri, "team")
    res = _sweep(tmp_path, "--mlflow", uri, "--mlflow-experiment", "team")
    assert res.exit_code == 0, res.output
    n = len(seen["rows"])
    assert seen["mlflow_runs_after_each"] == list(range(1, n + 1))   # live, one per run
    assert f"mlflow:    {n} run(s) logged to experiment 'team'" in res.stdout
    client = MlflowClient(tracking_uri=uri)
    exp = client.get_experiment_by_name("team")
    logged = client.search_runs([exp.experiment_id], max_results=1000)
    (parent,) = [r for r in logged if r.data.tags["sim2radar.kind"] == "sweep"]
    assert len(logged) == n + 1 and parent.info.status == "FINISHED"
    assert "primary.mean_diff" in parent.data.metrics

    # the same folder through sweep-report: nothing new
    report = CliRunner().invoke(app, ["sweep-report", str(tmp_path / "out" / "t"), "--mlflow",
                                      uri, "--mlflow-experiment", "team"])
    assert report.exit_code == 0, report.output
    assert f"mlflow:    0 run(s) logged (0 replacing older ones), {n} already there" in (
        report.stdout)
    assert len(client.search_runs([exp.experiment_id], max_results=1000)) == n + 1


def test_a_tracker_that_is_down_warns_once_and_the_sweep_finishes(tmp_path, monkeypatch):
    monkeypatch.setenv("MLFLOW_HTTP_REQUEST_MAX_RETRIES", "0")    # MLflow's default: ~4 min
    monkeypatch.setenv("MLFLOW_HTTP_REQUEST_TIMEOUT", "2")
    _fake_flow(monkeypatch, tmp_path)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    res = _sweep(tmp_path, "--mlflow", f"http://127.0.0.1:{port}")
    assert res.exit_code == 0, res.output
    assert res.stderr.count("warning: MLflow logging stopped") == 1, res.stderr
    assert "Connection refused" in res.stderr and "sim2radar sweep-report" in res.stderr
    assert "results:" in res.stdout and "mlflow:    logging stopped" in res.stdout
    assert len(pq.read_table(tmp_path / "out" / "t" / "runs.parquet")) == 18

    # sweep-report, whose point is the logging, fails with exit 1 (the report is written)
    report = CliRunner().invoke(app, ["sweep-report", str(tmp_path / "out" / "t"), "--mlflow",
                                      f"http://127.0.0.1:{port}"])
    assert report.exit_code == 1 and "Connection refused" in report.stderr


def test_mlflow_without_the_extra_fails_before_any_work(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "mlflow", None)              # `import mlflow` fails
    res = _sweep(tmp_path, "--mlflow", "sqlite:///m.db")          # SIM and REAL do not exist
    assert res.exit_code == 2
    assert "pip install 'sim2radar[mlflow]'" in res.stderr and "SIM" not in res.stderr
    assert not (tmp_path / "out").exists() and not (tmp_path / "store").exists()
    folder = tmp_path / "done"
    _constructed_sweep(folder)
    report = CliRunner().invoke(app, ["sweep-report", str(folder), "--mlflow", "sqlite:///m.db"])
    assert report.exit_code == 2 and "pip install 'sim2radar[mlflow]'" in report.stderr
    assert not (folder / "results.md").exists()                   # failed before writing
