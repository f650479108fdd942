"""The experiment sweep as a Prefect flow: every cell runs once, reruns skip, a killed sweep
resumes, a broken frame fails only the runs that read it, and the outputs are written."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from sim2radar.datasets import make_door_frames, write_dataset, write_metadata
from sim2radar.storage import ArtifactStore, get_schema

REPO = Path(__file__).resolve().parents[2]
PROXY = "proxy-real (reference radar simulation)"


def _write(root: Path, seed: int, n: dict[str, int], first_world: int, proxy: bool = False):
    frames = make_door_frames(sum(n.values()), seed=seed, points_per_frame=300)
    splits, i = {}, 0
    renamed = []
    for split, count in n.items():
        splits[split] = []
        for _k in range(count):
            f = frames[i]
            fid = f"world_{first_world + i // 2:06d}_f{i % 2:03d}"
            renamed.append(type(f)(fid, f.points, f.boxes, f.names))
            splits[split].append(fid)
            i += 1
    write_dataset(root, renamed, splits)
    if proxy:
        write_metadata(root, {"domain": PROXY})
    return root


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("sweep")
    sim = _write(root / "sim", 1, {"train": 8, "val": 2, "test": 2}, 0)
    real = _write(root / "real", 2, {"train": 8, "val": 4, "test": 4}, 100_000, proxy=True)
    return {"root": root, "sim": sim, "real": real}


def _sweep(sim, real, *, datasets=None, out="out/sweeps", store="out/store", **fields):
    """The sweep flow on a request (a failed run: Failed in Prefect, the summary here)."""
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.run_experiment import run_experiment
    from sim2radar.tasks.sweep import SweepRequest

    request = SweepRequest(sim=str(sim), real=str(real), out=str(out), store=str(store),
                           datasets={k: str(v) for k, v in (datasets or {}).items()}, **fields)
    return run_flow(run_experiment, request=request)


@pytest.fixture(scope="module")
def first(data, prefect_server):

    out, store = data["root"] / "sweeps", data["root"] / "store"
    summary = _sweep(data["sim"], data["real"], profile="smoke", name="t", out=out,
                             store=store)
    return {"summary": summary, "out": out, "store": store, "dir": out / "t"}


def test_every_cell_runs_once_and_the_outputs_are_written(first):
    s, d = first["summary"], first["dir"]
    assert s["counts"] == {"ok": 8, "skipped": 0, "failed": 0}   # 2 fractions x 2 trials x 2
    table = pq.read_table(d / "runs.parquet")
    get_schema("experiment_runs").validate(table)
    rows = table.to_pylist()
    assert sorted({(r["condition"], r["fraction"], r["trial"]) for r in rows}) == sorted(
        (c, f, t) for c in ("baseline", "sim-pretrain") for f in (0.5, 1.0) for t in (0, 1))
    # pairs see the same real frames; pre-trained runs name their (per-trial) pre-training
    for r in rows:
        assert r["n_real_frames"] == {0.5: 4, 1.0: 8}[r["fraction"]]
        assert (r["pretrain_key"] is None) == (r["condition"] == "baseline")
        assert r["history_val_epoch"] == [1, 2] and len(r["history_loss"]) == 2
    # one pre-training per trial and fraction: its sim intensities matched to that subset
    assert len({r["pretrain_key"] for r in rows if r["pretrain_key"]}) == 4
    assert len(list((d / "pretrain").iterdir())) == 4
    stats = json.loads((d / "stats.json").read_text())
    assert {c["n"] for c in stats["cells"]} == {2}
    sweep = json.loads((d / "sweep.json").read_text())
    assert sweep["real_is_proxy"] and sweep["datasets"]["real"]["domain"] == PROXY
    matches = sweep["intensity_match"]                     # one per pre-training ...
    assert sorted(matches) == ["pretrain-sim-t0-f0.5", "pretrain-sim-t0-f1", "pretrain-sim-t1-f0.5",
                               "pretrain-sim-t1-f1"]
    for pid, m in matches.items():                         # ... fitted on its runs' subset
        assert m["n_real_frames"] == (4 if pid.endswith("f0.5") else 8)
    md = (d / "results.md").read_text()
    assert "proxy" in md and "not claims about measured radar" in md
    html = (d / "dashboard.html").read_text()
    assert "<html" in html.lower()
    assert json.loads((d / "progress.json").read_text())["finished"] == 8
    # every pre-training checked before fine-tuning: trained on the sim set less its val split
    # (10 of 12 frames), checked on those 2 held-out frames and on the 4 real val frames
    pre = pq.read_table(d / "pretrainings.parquet")
    get_schema("experiment_pretrain").validate(pre)
    pre_rows = pre.to_pylist()
    assert sorted(r["pretrain_key"] for r in pre_rows) == sorted(
        {r["pretrain_key"] for r in rows if r["pretrain_key"]})
    for r in pre_rows:
        assert (r["n_sim_frames"], r["n_heldout_frames"], r["n_real_val_frames"]) == (10, 2, 4)
        assert r["holdout_split"] == "val" and r["conditions"] == ["sim-pretrain"]
        assert r["status"] == "ok" and len(r["history_loss"]) == r["epochs"] >= 1
        for col in ("train", "heldout", "zero_shot"):
            assert 0.0 <= r[f"{col}_ap_3d_r40_iou03"] <= 100.0
        check = json.loads((d / "pretrain" / r["pretrain_key"] / "check.json").read_text())
        assert check["sim_ap"] == r["heldout_ap_3d_r40_iou03"]
        done = json.loads((d / "pretrain" / r["pretrain_key"] / "done.json").read_text())
        assert done["frames"] == 10
    st = ArtifactStore(first["store"])
    assert all(st.exists("experiment_pretrain", r["pretrain_key"]) for r in pre_rows)
    assert len(stats["pretrainings"]["rows"]) == 4 and stats["pretrainings"]["summary"][0][
        "condition"] == "sim-pretrain"
    (pooled,) = stats["pooled"]          # the smoke grid's fractions (50, 100 %): the smaller
    assert pooled["primary"] and pooled["fractions"] == [0.5] and pooled["n_pairs"] == 2
    assert "## Primary endpoint" in md and "## Pre-trainings" in md


def test_prefect_artifacts_are_published(first):
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterKey

    async def keys():
        async with get_client() as client:
            arts = await client.read_artifacts(
                artifact_filter=ArtifactFilter(key=ArtifactFilterKey(like_="sweep-t-")))
            return {a.key: a.type for a in arts}

    import asyncio

    found = asyncio.run(keys())
    assert found.get("sweep-t-results") == "table"
    assert found.get("sweep-t-summary") == "markdown"
    assert found.get("sweep-t-progress") == "progress"


def test_a_rerun_trains_nothing(first, data, monkeypatch, tmp_path):
    import shutil

    import sim2radar.detect.train as train_mod

    # rerun on a copy of the sweep and its store: a rerun rewrites the sweep's tables (its
    # pre-trainings "skipped"), and pytest-xdist's worksteal may run this test before the
    # ones that read the first run's
    out, store = tmp_path / "sweeps", tmp_path / "store"
    shutil.copytree(first["out"], out)
    shutil.copytree(first["store"], store)
    calls = []
    real_train = train_mod.train
    monkeypatch.setattr(train_mod, "train", lambda *a, **k: calls.append(1) or real_train(*a, **k))
    again = _sweep(data["sim"], data["real"], profile="smoke", name="t", out=out, store=store)
    assert again["counts"] == {"ok": 0, "skipped": 8, "failed": 0}
    assert calls == []                                     # pre-trainings found finished too
    pre = pq.read_table(out / "t" / "pretrainings.parquet").to_pylist()
    assert {r["status"] for r in pre} == {"skipped"} and len(pre) == 4
    assert again["stats"]["cells"] == first["summary"]["stats"]["cells"]


def test_the_diagnosis_arms_run_the_control_and_the_lower_encoder_lr(data, prefect_server):
    """ref-pretrain pre-trains on its own dataset (the reference radar on the sim worlds);
    sim-pretrain-lowlr loads the sim pre-training and fine-tunes its encoder at 0.1 x lr."""

    ref = _write(data["root"] / "ref", 3, {"train": 8, "val": 2, "test": 2}, 0)
    out, store = data["root"] / "diag", data["root"] / "diag-store"
    s = _sweep(data["sim"], data["real"], profile="smoke", name="d", out=out,
                       store=store, datasets={"ref": ref},
                       overrides={"trials": 1, "fractions": [1.0], "conditions": [
                           "baseline", "sim-pretrain-lowlr", "ref-pretrain"]})
    assert s["counts"] == {"ok": 3, "skipped": 0, "failed": 0}
    rows = {r["condition"]: r for r in pq.read_table(out / "d" / "runs.parquet").to_pylist()}
    pre = {r["sim_role"]: r for r in pq.read_table(out / "d" /
                                                   "pretrainings.parquet").to_pylist()}
    assert pre["ref"]["conditions"] == ["ref-pretrain"]
    assert pre["sim"]["conditions"] == ["sim-pretrain-lowlr"]
    assert rows["ref-pretrain"]["pretrain_key"] == pre["ref"]["pretrain_key"]
    cfg = json.loads((out / "d" / "runs" / rows["sim-pretrain-lowlr"]["run_key"] /
                      "config.json").read_text())
    assert cfg["optimization"]["encoder_lr_scale"] == 0.1
    base = json.loads((out / "d" / "runs" / rows["baseline"]["run_key"] /
                       "config.json").read_text())
    assert base["optimization"]["encoder_lr_scale"] == 1.0
    stats = s["stats"]
    assert [p["condition"] for p in stats["pooled"]] == ["sim-pretrain-lowlr", "ref-pretrain"]
    assert not any(p["primary"] for p in stats["pooled"])   # sim-pretrain is not in this sweep


def test_a_sweep_refuses_changed_settings_but_not_changed_execution(first, data):
    """The settings are fixed when the sweep is created: a rerun with a changed protocol (lr)
    is refused with the field named, one with changed execution (concurrency) runs."""
    from sim2radar.experiment.prepare import SweepSettingsChanged
    from sim2radar.tasks.experiment import prepare_sweep

    sweep = json.loads((first["dir"] / "sweep.json").read_text())
    # amp "auto" is decided once, when the sweep is planned: every run trains the same way
    assert isinstance(sweep["settings"]["detector"]["finetune"]["amp"], bool)
    # ... by measurement (or the table), recorded with its figures
    for stage in ("pretrain", "finetune"):
        decision = sweep["precision"][stage]
        assert decision["amp"] is sweep["settings"]["detector"][stage]["amp"]
        assert decision["source"] in ("probe", "recorded", "table")
        if decision["source"] != "table":
            assert decision["seconds_per_step"]["float32"] > 0
    md = (first["dir"] / "results.md").read_text()
    assert f"digest `{sweep['settings_digest']}`" in md and sweep["settings_fixed_at"] in md
    datasets = {"sim": data["sim"], "real": data["real"]}
    with pytest.raises(SweepSettingsChanged, match=r"(?s)profile\.lr: .*new sweep name"):
        prepare_sweep(datasets, profile="smoke", name="t", out=first["out"],
                      store=first["store"], overrides={"lr": 0.5})
    plan = prepare_sweep(datasets, profile="smoke", name="t", out=first["out"],
                         store=first["store"], overrides={"concurrent_runs": 3})
    assert plan.sweep.settings_fixed_at == sweep["settings_fixed_at"]
    assert plan.sweep.settings_digest == sweep["settings_digest"]
    assert plan.concurrent_runs == 3


def test_content_keys_keep_their_recipe(monkeypatch):
    """A rerun of an existing sweep finds its cached runs only while the keys' recipe (stage,
    stage version, input names, key inputs, code version) stays what it was: these literals are
    the keys sweeps have been written under since stage version 2 (2026-11-28). Change them
    only with EXPERIMENT_STAGE_VERSION, when every run must be recomputed."""
    from sim2radar.experiment.plan import (
        PretrainSpec,
        RunSpec,
        pretrain_key_inputs,
        run_key_inputs,
    )
    from sim2radar.experiment.profiles import ExperimentProfile
    from sim2radar.tasks import experiment as tasks

    monkeypatch.setattr(tasks, "package_versions", lambda: {"sim2radar": "0.0.0"})
    det = {"model": {"voxel_size_m": [0.2, 0.2, 4.0]}, "augmentation": {"flip": True},
           "optimization": {"lr": 0.003, "batch_size": 4, "epochs": 2}, "runtime": {"amp": False}}
    pre = PretrainSpec(condition="sim-pretrain", trial=0, seed=7, sim_role="sim", epochs=20,
                       fraction=0.5, real_ids=("a", "b"))
    run = RunSpec(condition="sim-pretrain", fraction=0.5, trial=0, seed=7, n_real=2,
                  pretrain=pre, epochs=200, train_ids=("a", "b"))
    pkey = tasks._key_of("pretrain", {"sim": "s" * 20}, pretrain_key_inputs(pre, det, {"q": [1.0]}))
    assert pkey == "eed4f037a0470cab6dca"
    assert tasks._key_of("finetune", {"real": "r" * 20}, run_key_inputs(
        run, ExperimentProfile(detector=Path("x.yaml")), det, pkey)) == "2f7151d9a38b2e81e3a1"


def test_a_paper_sized_plan_reaches_the_flow_as_a_file(data, tmp_path):
    """A paper-sized grid's plan (run subsets, one intensity match per pre-training) is over
    the 512 KiB Prefect's API accepts as a flow run's parameters — the study's first launch
    was refused with a 422 — so the flow is given the plan file's path, whatever the grid."""
    import inspect

    from prefect._internal.schemas.validators import validate_parameter_size

    from sim2radar.flows.run_experiment import run_experiment
    from sim2radar.tasks.experiment import prepare_sweep, read_plan
    from sim2radar.tasks.sweep import SweepRequest

    limit = 524_288  # Prefect 3's default server.flow_run max parameter size
    plan = prepare_sweep({"sim": data["sim"], "real": data["real"]}, profile="smoke",
                         name="big", out=tmp_path / "sweeps", store=tmp_path / "store",
                         overrides={"trials": 24, "pretrain_per_trial": True})
    path = Path(plan.plan_path)
    assert path == (tmp_path / "sweeps" / "big" / "plan.json").resolve()
    assert path.stat().st_size > limit and len(plan.pretrains) >= 24
    with pytest.raises(ValueError, match="less than 524,288 bytes"):
        validate_parameter_size({"plan": plan.model_dump(mode="json")}, limit)  # sent before
    # the request, naming the plan's path
    assert list(inspect.signature(run_experiment.fn).parameters) == ["request"]
    request = SweepRequest(sim=str(data["sim"]), real=str(data["real"]), plan_path=str(path))
    validate_parameter_size({"request": request.model_dump(mode="json")}, limit)  # sent now
    assert read_plan(path) == plan                            # typed, as prepared


def test_a_frame_broken_before_or_during_a_sweep_trains_nothing_on_it(data, prefect_server,
                                                                      tmp_path):
    """A frame broken before the sweep is refused up front, naming the file (every frame of
    every split is loaded first); one broken while the sweep is planned or running fails the
    runs with "changed while the sweep ran" instead of training on altered data, and the
    rerun after the fix finishes them."""
    from sim2radar.datasets import DatasetError
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.run_experiment import run_experiment
    from sim2radar.tasks.experiment import prepare_sweep
    from sim2radar.tasks.sweep import SweepRequest

    real = _write(tmp_path / "real", 2, {"train": 8, "val": 4, "test": 4}, 100_000, proxy=True)
    victim = real / "points" / f"{(real / 'ImageSets' / 'train.txt').read_text().split()[-1]}.npy"
    good = victim.read_bytes()
    kw = dict(profile="smoke", name="broken", out=tmp_path / "o", store=tmp_path / "store",
              overrides={"intensity_matching": False, "trials": 1})
    plan = prepare_sweep({"sim": data["sim"], "real": real}, **kw)
    victim.write_bytes(b"not a numpy file")
    with pytest.raises(DatasetError, match=f"{victim.name}: not a NumPy .npy array"):
        prepare_sweep({"sim": data["sim"], "real": real}, **kw)
    request = SweepRequest(sim=str(data["sim"]), real=str(real), plan_path=plan.plan_path)
    state = run_experiment(request, return_state=True)
    assert state.is_failed() and state.message == "4 of 4 runs failed (sweep broken)"
    s = run_flow(run_experiment, request=request)   # the summary, all the same
    rows = pq.read_table(tmp_path / "o" / "broken" / "runs.parquet").to_pylist()
    assert s["counts"]["failed"] == len(rows) == 4 and s["counts"]["ok"] == 0
    assert all("changed while the sweep ran" in r["error"] and r["ap_3d_r40_iou03"] is None
               for r in rows)
    victim.write_bytes(good)
    again = run_experiment(request.model_copy(update={
        "plan_path": prepare_sweep({"sim": data["sim"], "real": real}, **kw).plan_path}))
    assert again["counts"] == {"ok": 4, "skipped": 0, "failed": 0}


def test_a_published_sweep_rebuilds_its_report_from_its_raw_files(first, tmp_path):
    """sweep-report --publish copies the raw files (no checkpoints) and rebuilds results.md,
    stats.json and the dashboard from them: the same statistics and tables as the sweep's."""
    from typer.testing import CliRunner

    from sim2radar.cli import app

    dest = tmp_path / "docs" / "results" / "t"
    res = CliRunner().invoke(app, ["sweep-report", str(first["dir"]), "--publish", str(dest)])
    assert res.exit_code == 0, res.output
    names = sorted(p.name for p in dest.iterdir())
    assert {"sweep.json", "plan.json", "runs.parquet", "pretrainings.parquet", "stats.json",
            "results.md", "dashboard.html"} <= set(names)
    assert not (dest / "runs").exists() and not (dest / "pretrain").exists()
    ours = json.loads((first["dir"] / "stats.json").read_text())
    again = json.loads((dest / "stats.json").read_text())
    assert again["cells"] == ours["cells"] and again["pooled"] == ours["pooled"]
    assert again["pretrainings"] == ours["pretrainings"]
    md = (dest / "results.md").read_text()
    assert md.split("## Runs")[0] == (first["dir"] / "results.md").read_text().split(
        "## Runs")[0]
    # rebuilt in place, from the published folder alone
    (dest / "results.md").unlink()
    assert CliRunner().invoke(app, ["sweep-report", str(dest)]).exit_code == 0
    assert (dest / "results.md").read_text() == md
    # a published pre-registration is never replaced by another
    (first["dir"] / "preregistration.md").write_text("# the sweep's\n")
    (dest / "preregistration.md").write_text("# another\n")
    res = CliRunner().invoke(app, ["sweep-report", str(first["dir"]), "--publish", str(dest)])
    assert res.exit_code == 2 and "never replaced" in res.output
    (first["dir"] / "preregistration.md").unlink()
    res = CliRunner().invoke(app, ["sweep-report", str(tmp_path / "none")])
    assert res.exit_code == 2 and "sweep.json: not found" in res.output


def test_large_published_json_files_are_kept_compressed_and_still_read(first, tmp_path,
                                                                      monkeypatch):
    """A study's plan.json and sweep.json (one intensity match per pre-training) run to
    megabytes: published above 256 KiB as name.json.gz, byte for byte, and read from there."""
    import gzip

    from typer.testing import CliRunner

    import sim2radar.cli.experiment as cli_exp
    from sim2radar.cli import app
    from sim2radar.experiment.dashboard import dashboard_data, load_sweep

    monkeypatch.setattr(cli_exp, "PUBLISH_GZIP_BYTES", 1000)
    dest = tmp_path / "pub"
    res = CliRunner().invoke(app, ["sweep-report", str(first["dir"]), "--publish", str(dest)])
    assert res.exit_code == 0, res.output
    for name in ("plan.json", "sweep.json"):
        assert not (dest / name).exists()
        assert gzip.decompress((dest / (name + ".gz")).read_bytes()) == \
            (first["dir"] / name).read_bytes()
    data = dashboard_data(load_sweep(dest))
    assert data["name"] == "t" and data["banner"]["kind"] == "proxy"   # from sweep.json.gz
    assert (dest / "results.md").read_text().startswith("# Sweep t")


def test_bad_inputs_exit_2_with_one_line(data, tmp_path):
    from typer.testing import CliRunner

    from sim2radar.cli import app

    res = CliRunner().invoke(app, ["sweep", str(data["sim"]), str(tmp_path / "nope"),
                                   "--profile", "smoke", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "no such folder" in res.output
    res = CliRunner().invoke(app, ["sweep", str(data["sim"]), str(data["real"]),
                                   "--profile", "no-such-profile", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "bundled" in res.output
    res = CliRunner().invoke(app, ["sweep", str(data["sim"]), str(data["sim"]), "--profile",
                                   "smoke", "--out", str(tmp_path), "--ablations"])
    assert res.exit_code == 2 and "--sim-gt" in res.output


def test_a_condition_registered_at_run_time_runs_through_the_unchanged_cli(
        data, prefect_server, tmp_path, monkeypatch):
    """Issue #32: a new condition is one registry entry. Registered here with a new dataset
    role, it runs a smoke sweep from the command line (``--dataset ROLE=PATH``, no new
    option), its runs are recorded under its name, and an unknown role is refused."""
    from typer.testing import CliRunner

    from sim2radar.cli import app
    from sim2radar.experiment.profiles import CONDITIONS, Condition

    monkeypatch.setitem(CONDITIONS, "twin-pretrain", Condition(
        "twin-pretrain", "twin", False, "pre-trained on a twin sim dataset", "Twin Pretrain",
        "#17becf"))
    args = ["sweep", str(data["sim"]), str(data["real"]), "--profile", "smoke", "--name", "tw",
            "--out", str(tmp_path / "sweeps"), "--store", str(tmp_path / "store"),
            "--conditions", "baseline,twin-pretrain"]
    bad = CliRunner().invoke(app, [*args, "--dataset", "twins=x"])
    assert bad.exit_code == 2 and "known roles" in bad.output and "twin" in bad.output
    res = CliRunner().invoke(app, [*args, "--dataset", f"twin={data['sim']}"])
    assert res.exit_code == 0, res.output
    rows = pq.read_table(tmp_path / "sweeps" / "tw" / "runs.parquet").to_pylist()
    assert {r["condition"] for r in rows} == {"baseline", "twin-pretrain"}
    assert all(r["status"] == "ok" for r in rows)
    sweep = json.loads((tmp_path / "sweeps" / "tw" / "sweep.json").read_text())
    assert set(sweep["datasets"]) == {"real", "twin"}


def test_plan_prints_the_grid_cost_and_creates_nothing(data, tmp_path):
    from typer.testing import CliRunner

    from sim2radar.cli import app

    out = tmp_path / "sweeps"
    res = CliRunner().invoke(app, ["sweep", str(data["sim"]), str(data["real"]), "--profile",
                                   "smoke", "--name", "p", "--out", str(out), "--plan",
                                   "--plan-workers", "1,2", "--json", str(tmp_path / "c.json")])
    assert res.exit_code == 0, res.output
    assert "expected wall time on 2 worker(s)" in res.output and "measured here" in res.output
    assert not (out / "p").exists()                       # nothing planned into the folder
    cost = json.loads((tmp_path / "c.json").read_text())
    # smoke: 2 trials x 2 fractions -> 4 pre-trainings (1 epoch x ceil(10 / 4) steps: the 12
    # sim frames less the 2 of its held-out val split) and 8
    # runs (2 epochs x ceil(4 or 8 / 4))
    assert cost["jobs"] == {"pretrain": {"jobs": 4, "steps": 12},
                            "finetune": {"jobs": 8, "steps": 24}}
    res = CliRunner().invoke(app, ["sweep", str(data["sim"]), str(data["real"]), "--profile",
                                   "smoke", "--plan", "--step-seconds", "2,1", "--json",
                                   str(tmp_path / "g.json"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    given = json.loads((tmp_path / "g.json").read_text())
    assert not given["measured"]
    assert given["compute_hours"] == pytest.approx((12 * 2 + 24 * 1) / 3600)
    assert given["wall_hours"]["1"] == pytest.approx(given["compute_hours"])
    res = CliRunner().invoke(app, ["sweep", str(data["sim"]), str(data["real"]), "--profile",
                                   "smoke", "--plan", "--step-seconds", "fast"])
    assert res.exit_code == 2 and "--step-seconds" in res.output


def test_a_killed_sweep_resumes_and_only_finishes_the_missing_runs(data, tmp_path):
    """SIGKILL the sweep after its first finished run; the rerun skips what finished."""
    env = {**os.environ, "PREFECT_HOME": str(tmp_path / "prefect")}
    args = [sys.executable, "-c", "from sim2radar.cli import main; main()", "sweep",
            str(data["sim"]), str(data["real"]), "--profile", "smoke", "--name", "k",
            "--out", str(tmp_path / "o"), "--store", str(tmp_path / "store")]
    proc = subprocess.Popen(args, cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    runs = tmp_path / "o" / "k" / "runs.parquet"
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and not (runs.is_file()
                                                   and pq.read_table(runs).num_rows >= 1):
            time.sleep(0.2)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    listed = {r["run_key"] for r in pq.read_table(runs).to_pylist() if r["status"] == "ok"}
    # a run whose artifact was written but whose row had not reached runs.parquet when the
    # kill landed is finished too: the store is what the rerun trusts
    done = set(ArtifactStore(tmp_path / "store").keys("experiment_runs"))
    assert listed <= done and 1 <= len(done) < 8
    res = subprocess.run(args, cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    rows = pq.read_table(runs).to_pylist()
    assert len(rows) == 8
    status = {r["run_key"]: r["status"] for r in rows}
    assert all(status[k] == "skipped" for k in done)
    assert sum(v == "ok" for v in status.values()) == 8 - len(done)
    assert len(ArtifactStore(tmp_path / "store").keys("experiment_runs")) == 8
    assert np.isfinite([r["ap_3d_r40_iou03"] for r in rows]).all()


def test_a_sweep_on_a_dask_cluster_gives_the_thread_runners_results(first, data, tmp_path,
                                                                   monkeypatch):
    """The same smoke sweep with its runs on a 2-process LocalCluster (loopback) finishes every
    run and reports the thread runner's APs: training is seeded per run, not per process.
    The runs claim GPU slots (what ``--runs-per-gpu`` does on a cluster of GPU workers): each
    training task asks the scheduler for one GPU_RUNS unit, which the workers declare."""
    pytest.importorskip("prefect_dask")
    distributed = pytest.importorskip("distributed")
    from distributed.diagnostics.plugin import SchedulerPlugin

    import sim2radar.tasks.sweep as sweep_job
    from sim2radar.experiment.packing import GPU_RESOURCE
    from sim2radar.flows.runners import local_cluster_kwargs
    from sim2radar.tasks.experiment import prepare_sweep
    from sim2radar.tasks.runner import RunOptions

    class Restrictions(SchedulerPlugin):
        def __init__(self, scheduler):
            self.scheduler, self.seen, self.priority = scheduler, {}, {}

        def transition(self, key, start, finish, *args, **kwargs):
            if finish == "processing":
                ts = self.scheduler.tasks.get(key)
                self.seen[key] = dict(ts.resource_restrictions or {}) if ts else None
                self.priority[key] = (ts.annotations or {}).get("priority") if ts else None

    plan = prepare_sweep({"sim": data["sim"], "real": data["real"]}, profile="smoke",
                         name="t", out=tmp_path / "sweeps", store=tmp_path / "store")
    with distributed.LocalCluster(**local_cluster_kwargs(2),
                                  resources={GPU_RESOURCE: 1}) as lc:
        plugin = Restrictions(lc.scheduler)
        lc.scheduler.add_plugin(plugin, name="restrictions")
        # what --runs-per-gpu decides on a scheduler address (pack_runs needs a CUDA GPU)
        monkeypatch.setattr(sweep_job, "sweep_options", lambda plan, request: (
            RunOptions(workers=2, dask_address=lc.scheduler_address), {GPU_RESOURCE: 1}))
        summary = _sweep(data["sim"], data["real"], plan_path=plan.plan_path)
    assert summary["counts"] == {"ok": 8, "skipped": 0, "failed": 0}
    assert len(plugin.seen) == 8 + len(plan.pretrains)       # every training task ...
    assert all(r == {GPU_RESOURCE: 1} for r in plugin.seen.values()), plugin.seen  # ... a slot
    # ... and, all handed over at once on a scheduler address, its chain of steps as priority
    from sim2radar.experiment.cost import chain_steps, plan_jobs

    assert sorted(plugin.priority.values()) == sorted(chain_steps(plan_jobs(plan)).values())

    def aps(path):
        rows = pq.read_table(path).to_pylist()
        return {(r["condition"], r["fraction"], r["trial"]): r["ap_3d_r40_iou03"] for r in rows}

    on_dask, on_threads = aps(tmp_path / "sweeps" / "t" / "runs.parquet"), aps(
        first["dir"] / "runs.parquet")
    assert on_dask.keys() == on_threads.keys()
    assert on_dask == pytest.approx(on_threads, abs=1e-6)


def test_a_dask_worker_killed_mid_run_loses_nothing(data, prefect_server, tmp_path):
    """SIGKILL the Dask worker that is fine-tuning a run once the run has a checkpoint: Dask
    gives the task to a live worker, which takes over the dead worker's claim and resumes
    from ``last.pt``. Every run finishes once, no row is duplicated."""
    pytest.importorskip("prefect_dask")
    distributed = pytest.importorskip("distributed")
    import threading

    from sim2radar.experiment.claims import read_events
    from sim2radar.flows.runners import local_cluster_kwargs

    sweep = tmp_path / "sweeps" / "kill"
    killed: dict = {}
    stop = threading.Event()

    def killer():
        while not stop.is_set() and not killed:
            for path in (sweep / "claims").glob("*.json"):
                try:
                    holder = json.loads(path.read_text())
                except (OSError, ValueError):
                    continue
                run = sweep / "runs" / holder.get("key", "?")
                if (run / "last.pt").is_file() and holder.get("pid") != os.getpid():
                    os.kill(holder["pid"], signal.SIGKILL)
                    killed.update(holder)
                    return
            time.sleep(0.02)

    watcher = threading.Thread(target=killer, daemon=True)
    with distributed.LocalCluster(**local_cluster_kwargs(2)) as lc:
        watcher.start()
        try:
            summary = _sweep(data["sim"], data["real"], profile="smoke", name="kill",
                                     out=tmp_path / "sweeps", store=tmp_path / "store",
                                     dask_address=lc.scheduler_address,
                                     overrides={"finetune_epochs": 30, "val_every": 0})
        finally:
            stop.set()
            watcher.join(5)
    assert killed, "no run was caught mid-training"
    assert summary["counts"] == {"ok": 8, "skipped": 0, "failed": 0}
    rows = pq.read_table(sweep / "runs.parquet").to_pylist()
    assert len(rows) == len({r["run_key"] for r in rows}) == 8
    assert len(ArtifactStore(tmp_path / "store").keys("experiment_runs")) == 8
    events = read_events(sweep / "claims")
    victim = [e for e in events if e["key"] == killed["key"]]
    assert [e["event"] for e in victim] == ["claimed", "takeover", "claimed", "released"]
    assert victim[2]["resume"] is True and victim[2]["pid"] != killed["pid"]
    for key in {e["key"] for e in events}:                  # finished once each
        assert sum(e["event"] == "released" for e in events if e["key"] == key) == 1


def test_unsafe_sweep_inputs_are_refused_before_any_work(data, tmp_path, unwritable_dir):
    """Issue #24 probes 3, 4, 5, 7 and 8: each refused with exit 2 and one line naming the
    option, file or frame and the fix — before any folder is made or run trained."""
    import shutil

    from typer.testing import CliRunner

    from sim2radar.cli import app

    out = tmp_path / "sweeps"

    def sweep(sim, real, *more):
        res = CliRunner().invoke(app, ["sweep", str(sim), str(real), "--profile", "smoke",
                                       "--out", str(out), "--store", str(tmp_path / "store"),
                                       *more])
        assert res.exit_code == 2, res.output
        assert "Traceback" not in res.output and res.output.count("error:") == 1
        return " ".join(res.output.split())

    # the same dataset as SIM and REAL: pre-training would see the real test frames
    assert "is the real dataset" in sweep(data["real"], data["real"])
    # a SIM dataset holding one of REAL's test frames (a copy under another name)
    sim = tmp_path / "sim_leak"
    shutil.copytree(data["sim"], sim)
    test_id = (data["real"] / "ImageSets" / "test.txt").read_text().split()[0]
    leaked = (sim / "ImageSets" / "train.txt").read_text().split()[0]
    shutil.copy(data["real"] / "points" / f"{test_id}.npy", sim / "points" / f"{leaked}.npy")
    said = sweep(sim, data["real"])
    assert "shares 1 frame(s)" in said and f"= real {test_id}" in said
    # a sweep name is one folder under --out
    for name in ("..", ".", "../x", ".hidden"):
        assert "a sweep name is one folder name under --out" in sweep(
            data["sim"], data["real"], "--name", name)
    assert not list(tmp_path.glob("*.json")) and not list(out.glob("*.json"))  # nothing
    assert "--workers must be >= 1" in sweep(data["sim"], data["real"], "--workers", "0")
    # outputs that cannot be written
    assert "--out" in sweep(data["sim"], data["real"], "--out", str(unwritable_dir / "o"))
    # a frame of REAL's test split that does not load: found before the first run
    real = tmp_path / "real_bad"
    shutil.copytree(data["real"], real)
    bad = real / "points" / f"{test_id}.npy"
    pts = np.load(bad)
    pts[0, 0] = np.nan
    np.save(bad, pts)
    said = sweep(data["sim"], real, "--name", "bad")
    assert f"{bad}: points contain NaN or inf" in said
    assert not (out / "bad" / "runs").exists() and not (out / "bad" / "pretrain").exists()


def test_a_truncated_run_row_heals_and_force_run_redoes_a_run(data, prefect_server, tmp_path):
    """Issue #24 probe 2 for sweeps: a truncated experiment_runs file is quarantined and its
    run computed again (from its final checkpoint: same AP) instead of failing on every
    rerun; ``--force-run`` redoes a run from scratch, its old row and checkpoints kept aside."""

    kw = dict(profile="smoke", name="h", out=tmp_path / "o", store=tmp_path / "store",
              overrides={"trials": 1, "fractions": [1.0]})
    first = _sweep(data["sim"], data["real"], **kw)
    assert first["counts"] == {"ok": 2, "skipped": 0, "failed": 0}
    rows = {r["run_key"]: r for r in pq.read_table(tmp_path / "o/h/runs.parquet").to_pylist()}
    st = ArtifactStore(tmp_path / "store")
    key = next(k for k, r in rows.items() if r["condition"] == "baseline")
    path = Path(st.path("experiment_runs", key))
    path.write_bytes(path.read_bytes()[:300])
    again = _sweep(data["sim"], data["real"], **kw)
    assert again["counts"] == {"ok": 1, "skipped": 1, "failed": 0}
    healed = {r["run_key"]: r for r in pq.read_table(tmp_path / "o/h/runs.parquet").to_pylist()}
    assert healed[key]["status"] == "ok" and healed[key]["error"] == ""
    assert healed[key]["ap_3d_r40_iou03"] == pytest.approx(rows[key]["ap_3d_r40_iou03"])
    assert len(st.quarantined()) == 1

    forced = _sweep(data["sim"], data["real"], **kw, force=["baseline-f1-t0"])
    assert forced["counts"] == {"ok": 1, "skipped": 1, "failed": 0}
    assert len(st.quarantined()) == 2
    assert len(list((tmp_path / "o/h/quarantine/runs").iterdir())) == 1  # old checkpoints kept
    redone = {r["run_key"]: r for r in pq.read_table(tmp_path / "o/h/runs.parquet").to_pylist()}
    assert redone[key]["steps"] == rows[key]["steps"]  # trained from scratch, all its steps
    with pytest.raises(ValueError, match="no run or pre-training of this sweep has that id"):
        _sweep(data["sim"], data["real"], **kw, force=["baseline-f0.33-t9"])


def test_a_truncated_checkpoint_heals_and_force_run_redoes_a_pretraining(data, prefect_server,
                                                                          tmp_path):
    """Issue #33 probe 4: a pre-training whose last.pt was truncated after it finished is
    quarantined and trained again (same check, same encoder for its runs) instead of failing
    every run that loads it; a fine-tuning run's truncated last.pt resumes from its newest good
    epoch checkpoint; --force-run takes pre-training ids."""

    kw = dict(profile="smoke", name="c", out=tmp_path / "o", store=tmp_path / "store",
              overrides={"trials": 1, "fractions": [1.0], "finetune_epochs": 3,
                         "detector_overrides": {"runtime": {"checkpoint_every": 1,
                                                            "keep_checkpoints": 3}}})
    first = _sweep(data["sim"], data["real"], **kw)
    assert first["counts"] == {"ok": 2, "skipped": 0, "failed": 0}
    sweep = tmp_path / "o" / "c"
    (pre_dir,) = list((sweep / "pretrain").iterdir())
    before = json.loads((pre_dir / "check.json").read_text())
    ckpt = pre_dir / "last.pt"
    ckpt.write_bytes(ckpt.read_bytes()[:1000])           # truncated after it finished
    rows = {r["condition"]: r for r in pq.read_table(sweep / "runs.parquet").to_pylist()}
    st = ArtifactStore(tmp_path / "store")
    st.quarantine(st.path("experiment_runs", rows["sim-pretrain"]["run_key"]), "test")
    run_dir = sweep / "runs" / rows["sim-pretrain"]["run_key"]
    (run_dir / "last.pt").write_bytes((run_dir / "last.pt").read_bytes()[:500])
    again = _sweep(data["sim"], data["real"], **kw)
    assert again["counts"] == {"ok": 1, "skipped": 1, "failed": 0}
    assert (pre_dir / "quarantine").is_dir() and ckpt.is_file()
    after = json.loads((pre_dir / "check.json").read_text())
    assert after["sim_ap"] == before["sim_ap"] and after["train_ap"] == before["train_ap"]
    healed = {r["condition"]: r for r in pq.read_table(sweep / "runs.parquet").to_pylist()}
    assert healed["sim-pretrain"]["ap_3d_r40_iou03"] == pytest.approx(
        rows["sim-pretrain"]["ap_3d_r40_iou03"])              # resumed: the same run
    assert any(p.name.startswith("last.pt.") for p in (run_dir / "quarantine").iterdir())
    pre_id = next(iter(pq.read_table(sweep / "pretrainings.parquet").to_pylist()))["pretrain_id"]
    _sweep(data["sim"], data["real"], **kw, force=[pre_id])
    assert len(list((sweep / "quarantine" / "pretrain").iterdir())) == 1
    assert json.loads((pre_dir / "check.json").read_text())["sim_ap"] == before["sim_ap"]
