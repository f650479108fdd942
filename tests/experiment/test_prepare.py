"""Preparing a sweep without the store or Prefect (sim2radar/experiment/prepare.py): conditions and
dataset roles from the condition registry, the settings a sweep is fixed to, the plan with its
keys, context and sweep.json document, and the plan's round trip through plan.json."""

from __future__ import annotations

import hashlib
import json
import pickle

import pytest

from sim2radar.cli.experiment import sweep_flag
from sim2radar.datasets import make_door_frames, write_dataset, write_metadata
from sim2radar.detect.config import DetectConfig
from sim2radar.experiment.cost import plan_jobs, sweep_cost
from sim2radar.experiment.data import open_domain
from sim2radar.experiment.documents import DocumentError, SweepDocument
from sim2radar.experiment.errors import SettingError
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.plan import SweepPlan, pretrain_key_inputs, run_key_inputs
from sim2radar.experiment.prepare import (
    SweepSettingsChanged,
    build_plan,
    open_datasets,
    resolve_profile,
    settings_fixed_at,
    setup_sweep,
    sweep_conditions,
)
from sim2radar.experiment.profiles import ABLATIONS, CONDITIONS, ROLES


def _write(root, seed, n, first_world, proxy=False):
    frames = make_door_frames(sum(n.values()), seed=seed, points_per_frame=200)
    named, splits, i = [], {}, 0
    for split, count in n.items():
        splits[split] = []
        for _ in range(count):
            fid = f"world_{first_world + i // 2:06d}_f{i % 2:03d}"
            named.append(type(frames[i])(fid, frames[i].points, frames[i].boxes, frames[i].names))
            splits[split].append(fid)
            i += 1
    write_dataset(root, named, splits)
    if proxy:
        write_metadata(root, {"domain": "proxy-real (reference radar simulation)"})
    return root


@pytest.fixture(scope="module")
def domains(tmp_path_factory):
    root = tmp_path_factory.mktemp("sweep-data")
    return {"real": open_domain(_write(root / "real", 2, {"train": 8, "val": 2, "test": 2},
                                       100_000, proxy=True), "real"),
            "sim": open_domain(_write(root / "sim", 1, {"train": 8}, 0), "sim"),
            "sim-gt": open_domain(_write(root / "gt", 3, {"train": 4}, 50_000), "sim-gt")}


def _key_of(kind, inputs, key_inputs):
    """A stand-in for storage.content_key: readable kind and inputs, hashed key inputs."""
    digest = hashlib.sha256(json.dumps(key_inputs, sort_keys=True).encode()).hexdigest()[:8]
    return f"{kind}:{','.join(f'{k}={v}' for k, v in inputs.items())}:{digest}"


def _plan(setup, domains, tmp_path):
    return build_plan(setup, domains, name="t", sweep_dir=str(tmp_path), store="mem://",
                      fixed_at="2026-01-01T00:00:00+00:00", key_of=_key_of,
                      provenance={"versions": {"sim2radar": "x"}, "code": {"stage_version": 1}})


def test_conditions_and_dataset_roles_come_from_the_registry():
    prof = resolve_profile("smoke")
    assert sweep_conditions(prof, False, {"sim": "s", "real": "r"}) == (
        ("baseline", "sim-pretrain"), ("real", "sim"))
    # every dataset role is a condition's (or real); the library names the missing datasets
    # by role, the command line spells them as its options
    for cond in CONDITIONS.values():
        if cond.sim_role:
            assert cond.sim_role in ROLES
    with pytest.raises(SettingError, match="sim-gt-pretrain.*need the dataset.*the sim-gt "
                                           "dataset, the sim-one-material dataset") as err:
        sweep_conditions(prof, True, {"sim": "s", "real": "r", "sim-gt": None})
    assert "--" not in str(err.value)
    assert err.value.settings == ["dataset:sim-gt", "dataset:sim-one-material"]
    assert "need the dataset(s) --sim-gt, --sim-one-material" in err.value.spelled(sweep_flag)
    conds, roles = sweep_conditions(prof, True, {r: r for r in ROLES})
    assert set(conds) == {"baseline", "sim-pretrain", *ABLATIONS}
    assert roles == ("real", "sim", "sim-gt", "sim-one-material")
    # the diagnosis conditions are main conditions a profile lists: the control needs --ref
    every = resolve_profile("smoke", {"conditions": [c for c in CONDITIONS if c not in ABLATIONS],
                                      "ablations": list(ABLATIONS)})
    with pytest.raises(SettingError, match="ref-pretrain need the dataset.*the ref dataset"
                       ) as err:
        sweep_conditions(every, False, {r: r for r in ROLES if r != "ref"})
    assert err.value.spelled(sweep_flag).endswith("need the dataset(s) --ref")
    conds, roles = sweep_conditions(every, False, {r: r for r in ROLES})
    assert set(conds) == set(CONDITIONS) and roles == ROLES
    with pytest.raises(ValueError, match="unknown dataset role.*'sim-noisy'.*known"):
        sweep_conditions(prof, False, {"sim": "s", "real": "r", "sim-noisy": "n"})
    with pytest.raises(ValueError, match="overrides"):
        resolve_profile("smoke", {"trials": 0})


def test_a_sweeps_settings_are_fixed_by_its_first_preparation(tmp_path):
    settings = setup_sweep("smoke", {"sim": "s", "real": "r"}).settings
    first = settings_fixed_at(None, settings, name="t", sweep_dir=tmp_path)
    old = SweepDocument(name="t", settings=settings, settings_fixed_at=first,
                        created_at="earlier")
    assert settings_fixed_at(old, settings, name="t", sweep_dir=tmp_path) == first
    # a folder from before settings were recorded adopts the current ones
    assert settings_fixed_at(SweepDocument(name="t", created_at="c"), settings, name="t",
                             sweep_dir=tmp_path) == "c"
    changed = setup_sweep("smoke", {"sim": "s", "real": "r"}, overrides={"lr": 0.5}).settings
    with pytest.raises(SweepSettingsChanged, match=r"(?s)profile\.lr: 0\.003 -> 0\.5.*new sweep "
                       r"name \(the sweep name\)") as err:
        settings_fixed_at(old, changed, name="t", sweep_dir=tmp_path)
    assert "start a new sweep name (--name)" in err.value.spelled(sweep_flag)
    # execution-only fields do not count
    same = setup_sweep("smoke", {"sim": "s", "real": "r"}, overrides={"concurrent_runs": 4})
    assert settings_fixed_at(old, same.settings, name="t", sweep_dir=tmp_path) == first


def test_a_damaged_sweep_json_is_refused_in_one_line_not_skipped(tmp_path):
    """Issue #33 probe 6: a sweep.json of [], settings null or a string, or one whose settings
    were deleted (but whose digest remains) is refused with one line; it never silently skips
    the changed-settings check: the typed read (SweepFolder.read_sweep_document, which
    prepare_sweep uses) refuses them."""
    for doc, match in (([], "holds list"), ({"name": "t", "settings": None},
                                            "field 'settings' is None"),
                       ({"name": "t", "settings": "abc"}, "field 'settings' is 'abc'"),
                       ({"name": "t", "settings_digest": "d", "created_at": "c"},
                        "settings digest.*edited")):
        (tmp_path / "sweep.json").write_text(json.dumps(doc))
        with pytest.raises(DocumentError, match=match) as info:
            SweepFolder(tmp_path).read_sweep_document()
        assert "\n" not in str(info.value) and "sweep.json: " in str(info.value)


def test_the_plan_keys_every_job_from_its_key_inputs(domains, tmp_path):
    setup = setup_sweep("smoke", {"sim": "s", "real": "r"}, device="cpu")
    plan = _plan(setup, domains, tmp_path)
    assert (len(plan.pretrains), len(plan.runs)) == (4, 8)     # 2 trials x 2 fractions
    ctx = plan.context
    assert sorted(ctx.datasets) == sorted(plan.sweep.datasets) == ["real", "sim"]
    assert ctx.datasets["real"].key == domains["real"].key and ctx.device == "cpu"
    assert ctx.datasets["real"].ids(["test"]) == domains["real"].splits["test"]
    assert ctx.datasets["sim"].ids() == domains["sim"].ids()
    for p in plan.pretrains:
        assert p.intensity_match["n_real_frames"] == len(p.spec.real_ids)   # its runs' subset
        assert p.key == _key_of("pretrain", {"sim": domains["sim"].key}, pretrain_key_inputs(
            p.spec, ctx.pretrain_config.model_dump(mode="json"), p.intensity_match))
    by_id = {p.id: p for p in plan.pretrains}
    for r in plan.runs:
        pre = by_id.get(r.pretrain_id)
        assert r.pretrain_key == (pre.key if pre else None)
        assert r.key == _key_of("finetune", {"real": domains["real"].key}, run_key_inputs(
            r.spec, setup.profile, ctx.finetune_config.model_dump(mode="json"), r.pretrain_key))
        if pre:
            assert r in plan.runs_after(pre)
    assert len({r.key for r in plan.runs}) == 8
    # sweep.json: what the dashboard and the report read
    doc = plan.sweep.model_dump(mode="json")
    assert doc["conditions"] == ["baseline", "sim-pretrain"] and doc["n_runs"] == 8
    assert doc["real_is_proxy"] and doc["datasets"]["real"]["key"] == domains["real"].key
    assert sorted(doc["intensity_match"]) == sorted(by_id)
    assert doc["settings"] == setup.settings and doc["provenance"]["configs"]["finetune"] == \
        ctx.finetune_config.model_dump(mode="json")
    assert doc["settings_fixed_at"] == "2026-01-01T00:00:00+00:00"
    # the device is no part of a run's identity
    other = _plan(setup_sweep("smoke", {"sim": "s", "real": "r"}), domains, tmp_path)
    assert [r.key for r in other.runs] == [r.key for r in plan.runs]


def test_the_plan_travels_as_json_and_pickles(domains, tmp_path):
    plan = _plan(setup_sweep("smoke", {"sim": "s", "real": "r"}), domains, tmp_path)
    doc = json.loads(json.dumps(plan.model_dump(mode="json")))
    assert doc["format"] == 3 and "plan_path" not in doc
    again = SweepPlan.model_validate(doc)
    assert again == plan and again.model_dump(mode="json") == doc
    assert again.runs == plan.runs and again.pretrains == plan.pretrains
    assert again.context == plan.context and again.sweep == plan.sweep
    assert isinstance(again.context.finetune_config, DetectConfig)
    assert pickle.loads(pickle.dumps(plan)) == plan                 # to Dask workers
    # plan.json's layout: a run names its pre-training by id, beside its spec's fields
    run = next(r for r in doc["runs"] if r["pretrain_id"])
    assert "spec" not in run and "pretrain" not in run and run["id"] in {r.id for r in plan.runs}
    with pytest.raises(ValueError, match="plan format 1.*prepare the sweep again"):
        SweepPlan.model_validate({k: v for k, v in doc.items() if k != "format"})
    # --force-run names runs by id or key
    run = plan.runs[3]
    assert plan.find_runs([run.id, run.key, plan.runs[0].id]) == [run, plan.runs[0]]
    pre = plan.pretrains[1]                                       # ... and pre-trainings
    assert plan.find_runs([pre.id, run.id, pre.key]) == [pre, run]
    with pytest.raises(ValueError, match=r"no run or pre-training of this sweep.*look like "
                                         r"'baseline-f0\.5-t0' and pre-training ids like") as err:
        plan.find_runs(["baseline-f0.33-t9"])
    assert str(err.value).startswith("the runs to redo 'baseline-f0.33-t9': no run")
    assert err.value.spelled(sweep_flag).startswith("--force-run 'baseline-f0.33-t9': no run")
    again = pickle.loads(pickle.dumps(err.value))       # a Dask worker's error comes back whole
    assert type(again) is SettingError and again.spelled(sweep_flag) == err.value.spelled(
        sweep_flag)


def test_a_plan_refuses_a_real_dataset_without_its_splits(domains, tmp_path):
    setup = setup_sweep("smoke", {"sim": "s", "real": "r"}, overrides={"eval_split": "none"})
    with pytest.raises(ValueError, match="none.txt lists no frame"):
        _plan(setup, domains, tmp_path)


def test_cost_with_given_seconds_per_step(domains, tmp_path):
    setup = setup_sweep("smoke", {"sim": "s", "real": "r"})
    cost = sweep_cost(setup, domains, workers=(1, 2),
                      step_seconds={"pretrain": 2.0, "finetune": 1.0})
    # 4 pre-trainings of 1 epoch x ceil(8 / 4) steps; 8 runs of 2 epochs x ceil(4 or 8 / 4)
    assert cost["jobs"] == {"pretrain": {"jobs": 4, "steps": 8},
                            "finetune": {"jobs": 8, "steps": 24}}
    assert cost["compute_hours"] == pytest.approx((8 * 2 + 24) / 3600)
    assert cost["wall_hours"][1] == pytest.approx(cost["compute_hours"])
    assert cost["wall_hours"][2] < cost["wall_hours"][1] and not cost["measured"]
    # runs sharing one device, measured twice as fast alone: the tail shortens, the work not
    alone, shared = (sweep_cost(setup, domains, workers=(3,), step_seconds={
        "pretrain": 2.0, "finetune": 1.0}, throughput=t) for t in (None, {1: 3.0, 3: 3.0}))
    assert shared["compute_hours"] == alone["compute_hours"]
    assert shared["wall_hours"][3] < alone["wall_hours"][3]
    # the prepared plan's jobs (what the sweep dispatches by) have the same steps
    jobs = plan_jobs(_plan(setup, domains, tmp_path))
    assert sum(j.steps for j in jobs if j.kind == "pretrain") == 8
    assert sum(j.steps for j in jobs if j.kind == "finetune") == 24


def test_datasets_are_folders_or_exported_from_the_store(domains, tmp_path):
    calls = []

    def export(role, name, geometry):
        calls.append((role, name, geometry))
        return domains[role].root

    sources = {"real": "store:reference", "sim": "store:demo", "sim-gt": "store:demo:mine"}
    opened = open_datasets(sources, ("real", "sim", "sim-gt"), export)
    assert calls == [("real", "reference", "ground_truth"), ("sim", "demo", "reconstructed"),
                     ("sim-gt", "demo", "mine")]
    assert opened["real"].key == domains["real"].key and opened["sim-gt"].role == "sim-gt"
    assert open_datasets({"sim": domains["sim"].root}, ("sim",), export)["sim"].role == "sim"
    with pytest.raises(FileNotFoundError, match="sim dataset .*no such folder"):
        open_datasets({"sim": str(tmp_path / "nope")}, ("sim",), export)


def test_a_preregistered_profile_refuses_to_run_without_its_file_and_pins_it(tmp_path):
    from sim2radar.experiment.prepare import PreregistrationMissing

    pre = tmp_path / "preregistration.md"
    over = {"preregistered": True, "preregistration": pre}
    with pytest.raises(PreregistrationMissing, match=r"(?s)preregistration\.md.*cannot be read"
                                                     r".*before the first run"):
        setup_sweep("smoke", {"sim": "s", "real": "r"}, overrides=over)
    pre.write_text("   \n")
    with pytest.raises(PreregistrationMissing, match="is empty"):
        setup_sweep("smoke", {"sim": "s", "real": "r"}, overrides=over)
    pre.write_text("# Question\nDoes sim pre-training help at 5-25 %?\n")
    setup = setup_sweep("smoke", {"sim": "s", "real": "r"}, overrides=over)
    digest = hashlib.sha256(pre.read_bytes()).hexdigest()
    assert setup.settings["preregistration"] == {"sha256": digest}
    assert setup.preregistration["text"].startswith("# Question")
    # the file's path is not a setting (another checkout), its content is
    first = settings_fixed_at(None, setup.settings, name="t", sweep_dir=tmp_path)
    old = SweepDocument(name="t", settings=setup.settings, settings_fixed_at=first)
    moved = tmp_path / "elsewhere.md"
    moved.write_text(pre.read_text())
    again = setup_sweep("smoke", {"sim": "s", "real": "r"},
                        overrides={**over, "preregistration": moved})
    assert settings_fixed_at(old, again.settings, name="t", sweep_dir=tmp_path) == first
    pre.write_text("# Question\nDoes sim pre-training help at 50-100 %?\n")   # edited later
    edited = setup_sweep("smoke", {"sim": "s", "real": "r"}, overrides=over)
    with pytest.raises(SweepSettingsChanged, match="preregistration.sha256"):
        settings_fixed_at(old, edited.settings, name="t", sweep_dir=tmp_path)


def test_pretrainings_hold_out_the_sims_split_and_the_plan_names_their_conditions(tmp_path):
    root = tmp_path / "d"
    doms = {"real": open_domain(_write(root / "real", 2, {"train": 8, "val": 2, "test": 2},
                                       100_000, proxy=True), "real"),
            "sim": open_domain(_write(root / "sim", 1, {"train": 6, "val": 2}, 0), "sim")}
    setup = setup_sweep("smoke", {"sim": "s", "real": "r"},
                        overrides={"conditions": ["baseline", "sim-pretrain",
                                                  "sim-pretrain-lowlr"]})
    plan = _plan(setup, doms, tmp_path)
    assert all(p.spec.holdout_split == "val" and p.conditions == ("sim-pretrain",
                                                                    "sim-pretrain-lowlr")
               for p in plan.pretrains)
    low = [r for r in plan.runs if r.spec.condition == "sim-pretrain-lowlr"]
    sim = {(r.spec.fraction, r.spec.trial): r for r in plan.runs
           if r.spec.condition == "sim-pretrain"}
    for r in low:       # the same pre-training, another run
        twin = sim[(r.spec.fraction, r.spec.trial)]
        assert r.pretrain_key == twin.pretrain_key and r.key != twin.key
    # a pre-training's steps count the 6 frames it trains on, not the 2 held out: ceil(6 / 4)
    assert {j.steps for j in plan_jobs(plan) if j.kind == "pretrain"} == {2}


def test_labels_differing_only_in_case_or_no_label_at_all_are_refused_up_front(domains,
                                                                                tmp_path):
    """Issue #34, bring-your-own data: labels written ``Door`` passed every check and then all
    runs failed; now the plan refuses them naming the label file, and a real train split with
    no label of the detector's classes too."""
    import shutil

    from sim2radar.datasets.openpcdet import DatasetError

    setup = setup_sweep("smoke", {"sim": "s", "real": "r"})
    real = tmp_path / "real"
    shutil.copytree(domains["real"].root, real)
    label = sorted((real / "labels").glob("*.txt"))[0]
    label.write_text(label.read_text().replace(" door", " Door"))
    mixed = {**domains, "real": open_domain(real, "real")}
    with pytest.raises(DatasetError, match=rf"{label.name}: label class 'Door' is not 'door'"):
        _plan(setup, mixed, tmp_path / "p1")
    for f in (real / "labels").glob("*.txt"):
        f.write_text(f.read_text().replace(" Door", " window").replace(" door", " window"))
    none = {**domains, "real": open_domain(real, "real")}
    with pytest.raises(ValueError, match=r"its 'train' split holds no label of the detector's "
                                         r"classes \['door'\]"):
        _plan(setup, none, tmp_path / "p2")


def test_the_sweeps_plain_work_does_not_import_prefect():
    """The sweep's plain functions (prepare, ``--plan``'s cost, one training run, the tables)
    and its driver live in ``tasks/`` without Prefect; its flow is in ``flows/``."""
    import subprocess
    import sys

    code = ("import sys, sim2radar.tasks.experiment, sim2radar.tasks.sweep, "
            "sim2radar.experiment.prepare; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'prefect')[:3])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_a_sweep_folder_written_before_the_typed_records_still_loads():
    """The published diagnosis study (docs/results/diagnosis, written when the plan records
    were dataclasses with hand-written to_dict) loads as the typed records, and writes back
    the same JSON: sweep.json byte for byte, plan.json's runs, pre-trainings and document (its
    detector configs gain only the fields DetectConfig added since, at their defaults)."""
    import gzip
    from pathlib import Path

    folder = Path(__file__).resolve().parents[2] / "docs" / "results" / "diagnosis"
    sweep_doc = json.loads(gzip.decompress((folder / "sweep.json.gz").read_bytes()))
    typed = SweepDocument.model_validate(sweep_doc)
    assert typed.n_runs == 120 and typed.precision == {}       # written before precision
    assert json.dumps(typed.model_dump(mode="json")) == json.dumps(sweep_doc)
    doc = json.loads(gzip.decompress((folder / "plan.json.gz").read_bytes()))
    plan = SweepPlan.model_validate(doc)
    assert (len(plan.pretrains), len(plan.runs)) == (72, 120)
    again = plan.model_dump(mode="json")
    for part in ("format", "pretrains", "runs", "sweep", "concurrent_runs", "metric"):
        assert again[part] == doc[part], part
    assert list(again["runs"][0]) == list(doc["runs"][0])          # the same keys, in order
    ctx = {k: v for k, v in doc["context"].items() if not k.endswith("_config")}
    assert {k: again["context"][k] for k in ctx} == ctx
    for stage in ("pretrain_config", "finetune_config"):
        assert getattr(plan.context, stage) == DetectConfig.model_validate(doc["context"][stage])
    # a run's pre-training is the planned one, found by its id
    specs = {p.id: p.spec for p in plan.pretrains}
    for r in plan.runs:
        assert r.spec.pretrain == (specs[r.pretrain_id] if r.pretrain_id else None)
