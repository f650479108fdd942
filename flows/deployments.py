"""The project's Prefect deployments, from the installed package.

The definitions live in ``deployments.yaml`` beside this module (package data, so a wheel
carries them): name, description, tags, a **module** entrypoint
(``sim2radar.flows.simulate:simulate_dataset``), the default parameters and any schedules.
A worker that runs one imports the installed ``sim2radar``; nothing depends on a checkout.

    definitions()                                  the entries of deployments.yaml, checked
    runner_deployments(entries, target)            Prefect ``RunnerDeployment`` objects
    apply(entries, target) -> list[str]            register them on the current API
    prefect_yaml(target) -> str                    the same as a prefect.yaml (`prefect deploy`)

Where runs execute is part of the :class:`Target`: ``home`` becomes the process worker's
``working_dir`` (relative paths in the parameters — ``out/store``, ``scenes/**/*.yaml`` — are
relative to it) and is exported to the run as ``SIM2RADAR_HOME``. Prefect imports a module
entrypoint with the working folder first on ``sys.path``, so a ``sim2radar/`` package folder in
``home`` (a checkout) would shadow the installed package — the crash ``No module named
'sim2radar.flows'`` a checkout caused before: :func:`home_problem` refuses such a home unless
it is the very package that is installed (an editable install of that checkout).

Schedules are registered **inactive** unless ``Target.schedule`` is true: deploying never
queues nightly runs by itself; ``sim2radar deploy --schedule`` (or the Prefect UI's toggle)
turns them on.
"""

from __future__ import annotations

import dataclasses
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from sim2radar.configio import load_yaml

__all__ = ["DEFAULT_POOL", "DEFINITIONS", "Target", "apply", "definitions", "ensure_pool",
           "flow_of", "home_problem", "prefect_yaml", "runner_deployments", "select", "write_prefect_yaml"]

#: the package data file holding the definitions
DEFINITIONS = "deployments.yaml"
#: the work pool deployments go to unless told otherwise (a process pool)
DEFAULT_POOL = "sim2radar-cpu"
#: keys an entry may have, and those it must have
_KEYS = {"name", "description", "tags", "entrypoint", "parameters", "schedules"}
_REQUIRED = {"name", "entrypoint"}


@dataclasses.dataclass(frozen=True)
class Target:
    """Where and how the deployments run.

    Attributes
    ----------
    home : str
        Folder the runs execute in (the worker's ``working_dir``; exported as
        ``SIM2RADAR_HOME``). An absolute path, or a Prefect template such as
        ``{{ $SIM2RADAR_HOME }}`` in a generated prefect.yaml.
    pool : str
        Work pool name.
    queue : str
        Work queue of the pool.
    schedule : bool
        Register the schedules active (default: inactive, turned on by hand).
    """

    home: str
    pool: str = DEFAULT_POOL
    queue: str = "default"
    schedule: bool = False

    @property
    def job_variables(self) -> dict[str, Any]:
        """The process worker's job variables: working folder and environment."""
        return {"working_dir": self.home, "env": {"SIM2RADAR_HOME": self.home}}


def home_problem(home: str | Path) -> str | None:
    """Why runs cannot execute in ``home``, or None.

    A ``sim2radar/`` package folder there is imported instead of the installed package when
    Prefect loads the flow (it puts the working folder first on ``sys.path``); that is fine
    only when it *is* the installed package (an editable install of that checkout).
    """
    import sim2radar

    shadow = Path(home) / "sim2radar" / "__init__.py"
    if not shadow.is_file():
        return None
    installed = Path(sim2radar.__file__).resolve()
    if installed == shadow.resolve():
        return None
    return (f"{home} holds a sim2radar/ package folder (a checkout?), which Prefect would import "
            f"instead of the installed package ({installed.parent}) when a run starts there; "
            "give a --home without one (e.g. a data folder such as <checkout>/out), or run "
            "from an editable install of that checkout (pip install -e)")


def _source() -> str:
    return resources.files("sim2radar.flows").joinpath(DEFINITIONS).read_text()


def definitions() -> list[dict[str, Any]]:
    """The deployments declared in the package's ``deployments.yaml``, in file order.

    Raises
    ------
    ValueError
        An entry lacks a name or entrypoint, has an unknown key, a file-path entrypoint or a
        duplicate name (the message names the entry and the field).
    """
    doc = load_yaml(_source())
    entries = doc.get("deployments") if isinstance(doc, dict) else None
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"sim2radar/flows/{DEFINITIONS}: no `deployments:` list")
    seen = set()
    for i, entry in enumerate(entries):
        where = f"sim2radar/flows/{DEFINITIONS}: deployments[{i}]"
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: expected a mapping, got {type(entry).__name__}")
        if missing := _REQUIRED - entry.keys():
            raise ValueError(f"{where}: missing {', '.join(sorted(missing))}")
        if unknown := entry.keys() - _KEYS:
            raise ValueError(f"{where} ({entry['name']}): unknown key(s) "
                             f"{', '.join(sorted(unknown))}; known: {', '.join(sorted(_KEYS))}")
        if ".py:" in entry["entrypoint"] or "/" in entry["entrypoint"]:
            raise ValueError(f"{where} ({entry['name']}): entrypoint {entry['entrypoint']!r} is a "
                             "file path; give a module path (sim2radar.flows.<module>:<flow>)")
        if entry["name"] in seen:
            raise ValueError(f"{where}: the name {entry['name']!r} is used twice")
        seen.add(entry["name"])
    return entries


def select(entries: list[dict[str, Any]], names: list[str]) -> list[dict[str, Any]]:
    """The entries called ``names`` (a deployment name, or ``flow-name/deployment-name``), in
    the order given; every entry when ``names`` is empty.

    Raises
    ------
    KeyError
        A name matches no deployment (the message lists those there are).
    """
    if not names:
        return list(entries)
    by_name = {e["name"]: e for e in entries}
    chosen = []
    for name in names:
        entry = by_name.get(name.rsplit("/", 1)[-1])
        if entry is None:
            raise KeyError(f"no deployment {name!r}; there are: {', '.join(by_name)}")
        chosen.append(entry)
    return chosen


def flow_of(entry: dict[str, Any]):
    """The Prefect flow ``entry``'s entrypoint names (imported from the installed package)."""
    from prefect.flows import load_flow_from_entrypoint

    return load_flow_from_entrypoint(entry["entrypoint"])


def _schedules(entry: dict[str, Any], active: bool) -> list:
    from prefect.schedules import Cron

    return [Cron(s["cron"], timezone=s.get("timezone"), active=active)
            for s in entry.get("schedules") or []]


def runner_deployments(entries: list[dict[str, Any]], target: Target) -> list:
    """Prefect ``RunnerDeployment`` objects for ``entries`` with module-path entrypoints, the
    target's pool, queue, job variables and schedule activity. Loading each flow validates
    its default parameters (a bad default fails here, named, not at the first run)."""
    from prefect.deployments.runner import EntrypointType

    deployments = []
    for entry in entries:
        flow = flow_of(entry)
        flow.validate_parameters(entry.get("parameters") or {})
        dep = flow.to_deployment(
            name=entry["name"], description=" ".join(str(entry.get("description", "")).split()),
            tags=list(entry.get("tags") or []), parameters=dict(entry.get("parameters") or {}),
            schedules=_schedules(entry, target.schedule), work_pool_name=target.pool,
            work_queue_name=target.queue, job_variables=target.job_variables,
            entrypoint_type=EntrypointType.MODULE_PATH)
        deployments.append(dep)
    return deployments


def ensure_pool(name: str) -> bool:
    """Create the process work pool ``name`` on the current API unless it exists (with the
    process worker's default job template, as ``prefect work-pool create --type process``
    does). True when it was created."""
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.actions import WorkPoolCreate
    from prefect.exceptions import ObjectNotFound
    from prefect.workers.process import ProcessWorker

    with get_client(sync_client=True) as client:
        try:
            client.read_work_pool(name)
            return False
        except ObjectNotFound:
            client.create_work_pool(WorkPoolCreate(
                name=name, type="process",
                base_job_template=ProcessWorker.get_default_base_job_template()))
            return True


def apply(entries: list[dict[str, Any]], target: Target) -> list[str]:
    """Register ``entries`` on the current Prefect API; their ``flow/deployment`` names.
    Registering again updates them in place (same names)."""
    names = []
    for dep in runner_deployments(entries, target):
        dep.apply()
        names.append(f"{dep.flow_name}/{dep.name}")
    return names


def prefect_yaml(target: Target) -> str:
    """The definitions as a ``prefect.yaml`` for ``prefect deploy --prefect-file``: module
    entrypoints, a ``set_working_directory`` pull step and the job variables of ``target``
    (whose ``home`` may be a template such as ``{{ $SIM2RADAR_HOME }}``, which ``prefect
    deploy`` fills in from its environment), schedules active as ``target.schedule`` says."""
    from importlib.metadata import version

    deployments = []
    for entry in definitions():
        dep = {k: entry[k] for k in ("name", "description", "tags", "entrypoint", "parameters")
               if k in entry}
        if entry.get("schedules"):
            dep["schedules"] = [s | {"active": target.schedule} for s in entry["schedules"]]
        dep["work_pool"] = {"name": target.pool, "work_queue_name": target.queue,
                            "job_variables": target.job_variables}
        deployments.append(dep)
    doc = {"name": "sim2radar", "prefect-version": version("prefect"), "build": None,
           "push": None,
           "pull": [{"prefect.deployments.steps.set_working_directory": {
               "directory": target.home}}],
           "deployments": deployments}
    header = (
        "# Generated by `sim2radar deploy --prefect-yaml` from sim2radar/flows/deployments.yaml"
        " (edit that\n"
        "# file, then regenerate; tests/flows/test_deploy.py keeps the two equal).\n"
        "#\n"
        "#   export SIM2RADAR_HOME=/srv/sim2radar   # runs execute here; read at deploy time\n"
        "#   prefect work-pool create sim2radar-cpu --type process\n"
        "#   prefect --no-prompt deploy --all --prefect-file deploy/prefect.yaml\n"
        "#   prefect worker start --pool sim2radar-cpu\n"
        "#\n"
        + ("# Schedules are active.\n" if target.schedule else
           "# Schedules are inactive: turn them on in the UI, or regenerate with --schedule.\n")
        + "# See deploy/README.md.\n")
    return header + yaml.safe_dump(doc, sort_keys=False, width=96, allow_unicode=True)


def write_prefect_yaml(path: str | Path, target: Target) -> Path:
    """Write :func:`prefect_yaml` to ``path``; the path."""
    path = Path(path)
    path.write_text(prefect_yaml(target))
    return path
