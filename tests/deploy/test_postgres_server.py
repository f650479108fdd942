"""The factory on a Prefect server backed by PostgreSQL, as deploy/README.md describes it.

A throw-away PostgreSQL cluster (Debian's ``postgresql``: ``initdb`` + ``pg_ctl``, 127.0.0.1
on a free port, socket in a temporary folder) holds the database of a ``prefect server``
started with ``PREFECT_API_DATABASE_CONNECTION_URL=postgresql+asyncpg://…``. Against it, as
an operator would: ``prefect work-pool create``, ``prefect deploy`` of ``radar-on-demand``
and ``generate-on-demand`` from ``deploy/prefect.yaml``, a process worker, and ``prefect
deployment run … --watch`` of each: the built-in demo corridor, and one small procedural world
(the factory's main job), with the store in a temporary folder. The runs must finish
Completed, their flow and task runs must be rows of the Postgres database (and no SQLite file
may appear), and the store must hold the corridor's radar frames under the content key an
in-process run would use, with the metal end door detected where it stands, and the world's
dataset frames with their OpenPCDet export.

Every process (postgres, the Prefect server, the worker and its flow-run children) is
stopped at teardown, also on failure. ``make setup`` installs ``postgresql`` with apt; the
test is skipped only on a machine without apt. 30–45 s on 2 cores.
"""

from __future__ import annotations

import json
import os
import pwd
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from sim2radar.storage import ArtifactStore

REPO = Path(__file__).resolve().parents[2]
PREFECT_FILE = REPO / "deploy" / "prefect.yaml"
POOL = "sim2radar-cpu"  # the work pool deploy/prefect.yaml names
FLOW, DEPLOYMENT = "simulate-dataset", "radar-on-demand"
GEN_FLOW, GEN_DEPLOYMENT = "generate-dataset", "generate-on-demand"
DEMO_SCENE = "sim2radar/data/demo"  # relative to SIM2RADAR_HOME, where the worker runs
DB_USER, DB_NAME = "sim2radar", "prefect"
SERVER_START_S = 180.0  # Prefect server start incl. its migrations on an empty database [s]
RUN_TIMEOUT_S = 300  # deployment run: worker pick-up + flow run [s]
#: demo corridor, frame 0: radar at (0, 0, 1) m looking along the corridor (+x); the metal
#: door in the right wall spans x = 6.55-7.45 m, its face at y = -1.175 + 0.025 m (the end
#: door, at 8.95 m, lies beyond the ~8.5 m that TI's chain tests: its CFAR discards the last
#: 20 range bins and the anti-alias filter rolls off from 0.9 R_max = 8.7 m)
SIDE_DOOR_X_M, SIDE_DOOR_Y_M = (6.55, 7.45), -1.15
SIDE_DOOR_TOL_M = 0.2  # ~5 range bins of ti-mmwcas (c / 2B = 0.038 m)


def _postgres_bin() -> Path | None:
    """The newest ``/usr/lib/postgresql/<version>/bin`` holding initdb (Debian's layout)."""
    found = sorted(Path("/usr/lib/postgresql").glob("*/bin/initdb"),
                   key=lambda p: int(p.parts[-3]) if p.parts[-3].isdigit() else 0)
    return found[-1].parent if found else None


PG_BIN = _postgres_bin()
if PG_BIN is None:
    # a skip only where apt cannot install it; elsewhere missing binaries are a setup failure
    if shutil.which("apt-get") is None:
        pytest.skip("no apt on this machine to install Debian's postgresql: Postgres-backed "
                    "Prefect server test skipped", allow_module_level=True)
    pytest.fail("no /usr/lib/postgresql/*/bin/initdb: run `make setup` "
                "(or `sudo apt-get install postgresql`)", pytrace=False)


# --- processes -------------------------------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _children(pid: int) -> list[int]:
    """All descendants of ``pid`` (Linux /proc)."""
    parent_of: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            parent_of[int(stat.parent.name)] = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
    found, frontier = [], {pid}
    while frontier:
        frontier = {c for c, p in parent_of.items() if p in frontier}
        found += frontier
    return found


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _stop(proc: subprocess.Popen, timeout_s: float = 15.0) -> None:
    """Terminate ``proc``'s process group and every descendant (a worker's flow runs may run
    in sessions of their own); kill whatever is left after ``timeout_s``."""
    kids = _children(proc.pid)
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for send, pid in [(os.killpg, proc.pid)] + [(os.kill, k) for k in kids]:
            try:
                send(pid, sig)
            except (ProcessLookupError, PermissionError):
                pass
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if proc.poll() is not None and not any(_alive(k) for k in kids):
                return
            time.sleep(0.2)
    proc.wait(timeout=timeout_s)


def _start(cmd: list[str], log: Path, env: dict[str, str], cwd: Path = REPO) -> subprocess.Popen:
    """``cmd`` in its own session (so teardown can stop its whole group), output to ``log``."""
    with open(log, "ab") as out:
        return subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=cwd,
                                start_new_session=True)


def _tail(path: Path, n: int = 60) -> str:
    lines = path.read_text(errors="replace").splitlines() if path.exists() else []
    return f"--- last lines of {path} ---\n" + "\n".join(lines[-n:])


def _run(cmd: list[str], env: dict[str, str], timeout_s: float = 120.0,
         cwd: Path = REPO) -> str:
    """Run ``cmd``; its output, or a failure showing it."""
    done = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=timeout_s)
    out = done.stdout + done.stderr
    assert done.returncode == 0, f"{' '.join(cmd)} exited {done.returncode}:\n{out}"
    return out


# --- PostgreSQL ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Postgres:
    """A running throw-away cluster: ``url`` for Prefect, ``psql(sql)`` for checks."""

    port: int
    url: str

    def psql(self, sql: str) -> list[list[str]]:
        """Rows of ``sql`` on the Prefect database, as lists of strings."""
        out = _run([str(PG_BIN / "psql"), "-h", "127.0.0.1", "-p", str(self.port),
                    "-U", DB_USER, "-d", DB_NAME, "-X", "-A", "-t", "-F", "|", "-c", sql],
                   env=os.environ.copy(), timeout_s=30)
        return [line.split("|") for line in out.splitlines() if line]


def _cluster_owner() -> pwd.struct_passwd | None:
    """PostgreSQL refuses to run as root: as root, the cluster belongs to the ``postgres``
    user (made by Debian's package) or else ``nobody``; otherwise to us (None)."""
    if os.geteuid() != 0:
        return None
    for user in ("postgres", "nobody"):
        try:
            return pwd.getpwnam(user)
        except KeyError:
            continue
    pytest.fail("running as root with neither a 'postgres' nor a 'nobody' user to own the "
                "PostgreSQL cluster", pytrace=False)


@pytest.fixture
def postgres() -> Iterator[Postgres]:
    """initdb a cluster in a temporary folder, serve it on 127.0.0.1:<free port>, create the
    Prefect database; stop it and delete the folder afterwards."""
    # not pytest's tmp_path: its parents are 0700 root-only, the cluster owner must reach it
    base = Path(tempfile.mkdtemp(prefix="sim2radar-pg-"))
    data, sock, log = base / "data", base / "sock", base / "postgres.log"
    sock.mkdir()
    owner = _cluster_owner()
    as_owner = [] if owner is None else ["runuser", "-u", owner.pw_name, "--"]
    if owner is not None:
        for p in (base, sock):
            os.chown(p, owner.pw_uid, owner.pw_gid)
    env = os.environ | {"LC_ALL": "C"}
    port = _free_port()
    pg_ctl = [*as_owner, str(PG_BIN / "pg_ctl"), "-D", str(data)]
    try:
        _run([*as_owner, str(PG_BIN / "initdb"), "-D", str(data), "-U", DB_USER,
                                "-A", "trust", "-E", "UTF8", "--locale=C", "--no-sync",
                                "--no-instructions"], env=env, cwd=base)
        # loopback only; durability is not needed for a test database
        options = (f"-c listen_addresses=127.0.0.1 -p {port} -c unix_socket_directories={sock}"
                   " -c fsync=off -c synchronous_commit=off -c full_page_writes=off")
        _run([*pg_ctl, "-l", str(log), "-o", options, "-w", "-t", "60", "start"], env=env,
             cwd=base, timeout_s=90)
    except BaseException:
        print(_tail(log))
        subprocess.run([*pg_ctl, "-m", "immediate", "stop"], env=env, cwd=base,
                       capture_output=True, timeout=60)
        shutil.rmtree(base, ignore_errors=True)
        raise
    try:
        _run([str(PG_BIN / "createdb"), "-h", "127.0.0.1", "-p", str(port), "-U", DB_USER,
              DB_NAME], env=env, timeout_s=30)
        yield Postgres(port, f"postgresql+asyncpg://{DB_USER}@127.0.0.1:{port}/{DB_NAME}")
    finally:
        stopped = subprocess.run([*pg_ctl, "-m", "fast", "-t", "30", "stop"], env=env, cwd=base,
                                 capture_output=True, timeout=60)
        if stopped.returncode != 0 and (data / "postmaster.pid").exists():
            pid = int((data / "postmaster.pid").read_text().split()[0])
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        shutil.rmtree(base, ignore_errors=True)


# --- Prefect server on it --------------------------------------------------------------------


@dataclass(frozen=True)
class PrefectServer:
    api_url: str
    home: Path  # the server's PREFECT_HOME (where a SQLite database would have gone)
    log: Path


def _prefect_env(**settings: str) -> dict[str, str]:
    """This environment without any PREFECT_* setting of the test session, plus ``settings``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_")}
    return env | {"PREFECT_SERVER_ANALYTICS_ENABLED": "false", "COLUMNS": "200"} | settings


@pytest.fixture
def prefect_server(postgres: Postgres, tmp_path: Path) -> Iterator[PrefectServer]:
    """``prefect server start`` on 127.0.0.1:<free port> with its database in ``postgres``."""
    home, log, port = tmp_path / "server-home", tmp_path / "server.log", _free_port()
    env = _prefect_env(PREFECT_HOME=str(home), PREFECT_API_DATABASE_CONNECTION_URL=postgres.url,
                       PREFECT_SERVER_UI_ENABLED="false")
    proc = _start([sys.executable, "-m", "prefect", "server", "start", "--host", "127.0.0.1",
                   "--port", str(port)], log, env)
    api_url = f"http://127.0.0.1:{port}/api"
    try:
        deadline = time.monotonic() + SERVER_START_S
        while True:
            assert proc.poll() is None, f"prefect server exited {proc.returncode}\n{_tail(log)}"
            try:
                with urllib.request.urlopen(f"{api_url}/health", timeout=5) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            assert time.monotonic() < deadline, f"no /api/health in {SERVER_START_S} s\n{_tail(log)}"
            time.sleep(1.0)
        yield PrefectServer(api_url, home, log)
    finally:
        _stop(proc)


# --- the test --------------------------------------------------------------------------------


def test_deployment_run_on_a_postgres_backed_server_completes_and_stores_the_frames(
    postgres: Postgres, prefect_server: PrefectServer, tmp_path: Path
):
    from sim2radar.tasks.radar import scene_keys

    env = _prefect_env(PREFECT_API_URL=prefect_server.api_url,
                       PREFECT_HOME=str(tmp_path / "client-home"),
                       SIM2RADAR_HOME=str(REPO),  # templated into the pull step at deploy time
                       PREFECT_WORKER_QUERY_SECONDS="2")  # pick the run up quickly
    prefect = [sys.executable, "-m", "prefect"]
    _run([*prefect, "work-pool", "create", POOL, "--type", "process"], env)
    for name in (DEPLOYMENT, GEN_DEPLOYMENT):
        _run([*prefect, "--no-prompt", "deploy", "--name", name,
              "--prefect-file", str(PREFECT_FILE)], env)

    worker_log = tmp_path / "worker.log"
    worker = _start([*prefect, "worker", "start", "--pool", POOL], worker_log, env)
    store, png = tmp_path / "store", tmp_path / "bev"
    run_name = f"postgres-{uuid.uuid4().hex[:8]}"
    watch = ["--watch", "--watch-interval", "2", "--watch-timeout", str(RUN_TIMEOUT_S)]
    # each deployment takes one `request` parameter, a JSON object (it replaces the
    # deployment's default request whole: fields left out take the request model's defaults)
    scenes = {"scenes": [DEMO_SCENE], "store": str(store), "dataset": "postgres",
              "png_dir": str(png)}
    world = {"n_worlds": 1, "store": str(store), "dataset": "postgres-worlds",
             "spec": {"frames_per_world": 2, "geometry": "ground_truth",
                      "rig": {"width": 80, "height": 60}},
             "export_dir": str(tmp_path / "openpcdet")}
    try:
        out = _run([*prefect, "deployment", "run", f"{FLOW}/{DEPLOYMENT}",
                    "-p", f"request={json.dumps(scenes)}",
                    "--flow-run-name", run_name, *watch], env, timeout_s=RUN_TIMEOUT_S + 60)
        gen_out = _run([*prefect, "deployment", "run", f"{GEN_FLOW}/{GEN_DEPLOYMENT}",
                        "-p", f"request={json.dumps(world)}",
                        "--flow-run-name", f"{run_name}-gen", *watch],
                       env, timeout_s=RUN_TIMEOUT_S + 60)
    except AssertionError as e:
        raise AssertionError(f"{e}\n{_tail(worker_log)}\n{_tail(prefect_server.log)}") from None
    finally:
        _stop(worker)
    assert "Completed" in out, out
    assert "Completed" in gen_out, gen_out

    # the runs (one flow each, no subflow) and their unit and step tasks are rows of the
    # Postgres database ...
    rows = postgres.psql(
        "SELECT f.state_type, d.name FROM flow_run f JOIN deployment d ON d.id = f.deployment_id"
        f" WHERE f.name = '{run_name}'")
    assert rows == [["COMPLETED", DEPLOYMENT]]
    flows = postgres.psql("SELECT fl.name, f.state_type FROM flow_run f JOIN flow fl"
                          " ON fl.id = f.flow_id ORDER BY fl.name")
    assert flows == [[GEN_FLOW, "COMPLETED"], [FLOW, "COMPLETED"]]
    # the factory's steps as task runs, named by the manifest row: the world, its render and
    # its simulate step
    steps = postgres.psql("SELECT name, state_type FROM task_run WHERE name LIKE 'world%'"
                          " ORDER BY name")
    assert [name for name, _ in steps] == ["world_000000", "world_000000-render",
                                           "world_000000-simulate-ground_truth"], steps
    assert {state for _, state in steps} == {"COMPLETED"}
    tasks = postgres.psql("SELECT state_type FROM task_run WHERE name = 'demo_corridor'")
    assert tasks == [["COMPLETED"]]
    # ... and no SQLite database was made on the side
    assert not list(prefect_server.home.rglob("*.db")), list(prefect_server.home.rglob("*.db"))

    # the store holds the corridor's frames under the key an in-process run would use
    st = ArtifactStore(store)
    (row,) = st.manifest("postgres").rows()
    assert (row["scene_id"], row["status"]) == ("demo_corridor", "ok"), row
    key = scene_keys(REPO / DEMO_SCENE / "corridor.yaml", "ti-mmwcas")["radar_points"]
    assert row["artifacts"]["radar_points"] == key
    frames = st.read("radar_points", key).to_pylist()
    assert [f["frame_index"] for f in frames] == [0, 1, 2]  # the scene's three radar poses
    assert all(f["n_points"] > 0 for f in frames)
    assert len(list(png.glob("*.png"))) == 3
    # frame 0 looks down the corridor: the metal door in the right wall is detected where it
    # stands
    x, y = np.asarray(frames[0]["x_m"]), np.asarray(frames[0]["y_m"])
    along = (x >= SIDE_DOOR_X_M[0] - SIDE_DOOR_TOL_M) & (x <= SIDE_DOOR_X_M[1] + SIDE_DOOR_TOL_M)
    assert np.min(np.abs(y[along] - SIDE_DOOR_Y_M)) < SIDE_DOOR_TOL_M
    # the procedural world's dataset: its rows, its frames and their export
    counts = st.manifest("postgres-worlds").counts()
    assert counts["ok"] == 3 and counts["failed"] == 0, counts  # the world and its 2 frames
    assert len(list((tmp_path / "openpcdet" / "points").glob("*.npy"))) == 2
