"""deploy/prefect.yaml is consistent with the code: entrypoints load, parameters validate,
schedules parse; scene expansion for deployments."""

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
    assert "nightly-radar" in names
    nightly = next(d for d in doc["deployments"] if d["name"] == "nightly-radar")
    assert nightly["schedules"][0]["cron"] == "0 2 * * *"


def test_expand_scenes_folders_globs_and_files(tmp_path):
    from flows.simulate import expand_scenes

    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "one.yaml").write_text("meshes: []")
    (tmp_path / "a" / "two.yaml").write_text("meshes: []")
    missing = str(tmp_path / "missing.yaml")
    got = expand_scenes([tmp_path / "a", str(tmp_path / "a" / "*.yaml"), str(tmp_path / "none" / "*.yaml"), missing])
    assert got == [str(tmp_path / "a" / "one.yaml"), str(tmp_path / "a" / "two.yaml"), missing]
    with pytest.raises(FileNotFoundError, match="no scene files"):
        expand_scenes([str(tmp_path / "none" / "*.yaml")])
