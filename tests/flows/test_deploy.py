"""deploy/prefect.yaml is consistent with the code: entrypoints load, parameters validate,
schedules parse, the generate deployments' configs resolve; scene expansion for deployments."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]


def test_deployments_point_at_real_flows_with_valid_parameters(monkeypatch):
    from prefect.client.schemas.schedules import CronSchedule
    from prefect.flows import load_flow_from_entrypoint

    monkeypatch.chdir(REPO)
    doc = yaml.safe_load((REPO / "deploy" / "prefect.yaml").read_text())
    assert doc["prefect-version"] == "3.8.8"
    names = set()
    for dep in doc["deployments"]:
        names.add(dep["name"])
        flow = load_flow_from_entrypoint(dep["entrypoint"])
        flow.validate_parameters(dep.get("parameters", {}))  # raises on unknown / mistyped
        for sched in dep.get("schedules", []) or []:
            CronSchedule(cron=sched["cron"], timezone=sched.get("timezone"))
        assert dep["work_pool"]["name"]
    assert {"nightly-radar", "radar-on-demand", "nightly-generate", "generate-on-demand",
            "weekly-reference", "sweep-on-demand", "captures-on-demand"} <= names
    nightly = next(d for d in doc["deployments"] if d["name"] == "nightly-radar")
    assert nightly["schedules"][0]["cron"] == "0 2 * * *"


def _deployment(name):
    doc = yaml.safe_load((REPO / "deploy" / "prefect.yaml").read_text())
    return next(d for d in doc["deployments"] if d["name"] == name)


def test_generate_deployments_resolve_to_the_factory_job(monkeypatch):
    from prefect.client.schemas.schedules import CronSchedule
    from prefect.flows import load_flow_from_entrypoint

    monkeypatch.chdir(REPO)
    nightly = _deployment("nightly-generate")
    flow = load_flow_from_entrypoint(nightly["entrypoint"])
    assert flow.name == "generate-dataset"
    request = flow.validate_parameters(nightly["parameters"])["request"]
    # the request travels whole: Prefect validates the parameter into a GenerateRequest whose
    # DatasetSpec resolves the configs it names (preset names, radar preset, world/rig)
    spec = request.spec
    assert request.seeds == list(range(8)) and request.export_dir
    assert request.run.dask_address is None and request.run.workers == 1
    sched = CronSchedule(cron=nightly["schedules"][0]["cron"], timezone="UTC")
    assert sched.cron == "0 3 * * *"  # after nightly-radar (02:00)
    assert spec.geometries == ("reconstructed",) and spec.frames_per_world == 8
    assert spec.reconstruction.depth.name == "lidar"  # built-in backends, no weights
    on_demand = _deployment("generate-on-demand")
    assert not on_demand.get("schedules")
    given = {"request": on_demand["parameters"]["request"]
             | {"run": {"dask_address": "tcp://127.0.0.1:8786", "workers": 2}}}
    assert load_flow_from_entrypoint(on_demand["entrypoint"]).validate_parameters(
        given)["request"].run.workers == 2
    with pytest.raises(Exception, match="n_worlds"):
        flow.validate_parameters({"request": {"n_worlds": "many"}})
    # the server enforces the deployment's parameter schema (JSON Schema of the spec's input
    # form): the parameters in the file and a spec's own JSON form must both pass it
    import jsonschema
    from prefect.utilities.callables import parameter_schema

    schema = parameter_schema(flow).model_dump_for_openapi()
    for dep in (nightly, on_demand):
        jsonschema.validate(dep["parameters"], schema)
    jsonschema.validate({"request": {"spec": spec.to_dict(), "seeds": [0]}}, schema)
    with pytest.raises(jsonschema.ValidationError, match="frames"):
        jsonschema.validate({"request": {"spec": {"frames": 4}, "seeds": [0]}}, schema)


def test_expand_scenes_folders_globs_and_files(tmp_path):
    from sim2radar.scenes import expand_scenes

    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "one.yaml").write_text("meshes: []")
    (tmp_path / "a" / "two.yaml").write_text("meshes: []")
    missing = str(tmp_path / "missing.yaml")
    got = expand_scenes([tmp_path / "a", str(tmp_path / "a" / "*.yaml"), str(tmp_path / "none" / "*.yaml"), missing])
    assert got == [str(tmp_path / "a" / "one.yaml"), str(tmp_path / "a" / "two.yaml"), missing]
    with pytest.raises(FileNotFoundError, match="no scene files"):
        expand_scenes([str(tmp_path / "none" / "*.yaml")])


def test_the_captures_deployment_resolves_to_a_capture_spec(monkeypatch):
    from prefect.flows import load_flow_from_entrypoint

    from sim2radar.factory.captures import CaptureSpec

    monkeypatch.chdir(REPO)
    dep = _deployment("captures-on-demand")
    flow = load_flow_from_entrypoint(dep["entrypoint"])
    assert flow.name == "capture-dataset"
    spec = flow.validate_parameters(dep["parameters"])["request"].spec
    assert isinstance(spec, CaptureSpec)
    assert spec.poses.frames == 54 and spec.reconstruction.depth.name == "lidar"


def test_prefect_yaml_is_generated_from_the_package_definitions():
    """deploy/prefect.yaml (the `prefect deploy` path) is exactly what `sim2radar deploy
    --prefect-yaml` writes from the package's deployments.yaml: the two cannot drift."""
    from sim2radar.flows.deployments import Target, definitions, prefect_yaml

    expected = prefect_yaml(Target(home="{{ $SIM2RADAR_HOME }}"))
    assert (REPO / "deploy" / "prefect.yaml").read_text() == expected, (
        "deploy/prefect.yaml is stale: regenerate it with `sim2radar deploy --prefect-yaml "
        "deploy/prefect.yaml`")
    doc = yaml.safe_load(expected)
    assert [d["name"] for d in doc["deployments"]] == [d["name"] for d in definitions()]
    for dep in doc["deployments"]:
        assert not dep["entrypoint"].endswith(".py") and ".py:" not in dep["entrypoint"]
        assert all(s["active"] is False for s in dep.get("schedules", []))
        assert dep["work_pool"]["job_variables"]["working_dir"] == "{{ $SIM2RADAR_HOME }}"
    scheduled = yaml.safe_load(prefect_yaml(Target(home="/srv/x", schedule=True)))
    assert all(s["active"] for d in scheduled["deployments"] for s in d.get("schedules", []))
    assert scheduled["pull"][0]["prefect.deployments.steps.set_working_directory"] == {
        "directory": "/srv/x"}


def test_runner_deployments_carry_module_entrypoints_home_and_inactive_schedules(tmp_path):
    from sim2radar.flows.deployments import Target, definitions, runner_deployments, select

    entries = select(definitions(), ["simulate-dataset/nightly-radar", "weekly-reference"])
    deps = runner_deployments(entries, Target(home=str(tmp_path), pool="p", queue="q"))
    assert [d.name for d in deps] == ["nightly-radar", "weekly-reference"]
    for dep in deps:
        assert dep.entrypoint.startswith("sim2radar.flows.")
        assert dep.work_pool_name == "p" and dep.work_queue_name == "q"
        assert dep.job_variables == {"working_dir": str(tmp_path),
                                     "env": {"SIM2RADAR_HOME": str(tmp_path)}}
        assert dep.schedules and not any(s.active for s in dep.schedules)
    (active,) = runner_deployments(entries[:1], Target(home=str(tmp_path), schedule=True))
    assert all(s.active for s in active.schedules)
    with pytest.raises(KeyError, match="no deployment 'nightly'; there are: nightly-radar"):
        select(definitions(), ["nightly"])


def test_a_home_holding_another_sim2radar_package_is_refused(tmp_path):
    from sim2radar.flows.deployments import home_problem

    assert home_problem(tmp_path) is None
    assert home_problem(REPO) is None  # the editable install of this checkout: its own package
    (tmp_path / "sim2radar").mkdir()
    (tmp_path / "sim2radar" / "__init__.py").write_text("")
    assert "holds a sim2radar/ package folder" in home_problem(tmp_path)
