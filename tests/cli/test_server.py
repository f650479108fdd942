"""The managed local Prefect server (``sim2radar/cli/server.py``): one per ``PREFECT_HOME``.

Issue #16: a killed ``generate`` left Prefect's temporary API server (uvicorn) running,
re-parented to PID 1; five runs started at once on a fresh ``PREFECT_HOME`` crashed (SQLite
"duplicate column name" while two servers migrated one database, then "Timed out while
attempting to connect to ephemeral Prefect API server"). Here, real ``sim2radar generate``
processes on one fresh ``PREFECT_HOME``: five at once all finish and share one server; a run
killed by SIGKILL or SIGTERM leaves no process but that server; ``sim2radar server stop``
leaves none. A process belongs to a run when its environment holds the run's
``PREFECT_HOME`` (Linux ``/proc``). Every server is stopped at teardown; 127.0.0.1 only.
About 1 min on 2 cores (one server start, six tiny runs).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sim2radar.cli import app
from sim2radar.cli import server as srv

REPO = Path(__file__).resolve().parents[2]
CLI = [sys.executable, "-c", "from sim2radar.cli import main; main()"]
# the smallest real run: one world, 80 x 60 px at 2 spp, ground-truth geometry
TINY = ["--worlds", "1", "--width", "80", "--height", "60", "--spp", "2",
        "--geometry", "ground_truth", "--no-png"]

pytestmark = pytest.mark.skipif(not Path("/proc/self/environ").exists(),
                                reason="finds a run's processes through Linux /proc")


def _env(home: Path) -> dict[str, str]:
    env = {**os.environ, "PREFECT_HOME": str(home), srv.MODE_ENV: "managed",
           "PREFECT_SERVER_ANALYTICS_ENABLED": "false"}
    env.pop("PREFECT_API_URL", None)
    return env


def _processes_of(home: Path) -> dict[int, str]:
    """Every live process started with ``PREFECT_HOME=home``: pid -> command line."""
    entry = f"PREFECT_HOME={home}".encode()
    found = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) == os.getpid():
            continue
        try:
            if entry in (proc / "environ").read_bytes().split(b"\0"):
                found[int(proc.name)] = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:  # gone meanwhile, or not ours to read
            continue
    return found


def _settled(home: Path, expected: set[int], timeout_s: float = 15.0) -> dict[int, str]:
    """The processes of ``home`` once they are ``expected`` (or after ``timeout_s``)."""
    deadline = time.monotonic() + timeout_s
    while (found := _processes_of(home)).keys() != expected and time.monotonic() < deadline:
        time.sleep(0.2)
    return found


def _generate(home: Path, store: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, "generate", *TINY, "--out", str(store), *extra], cwd=REPO,
                          env=_env(home), capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def five_at_once(tmp_path_factory):
    """Five ``generate`` runs started together on one fresh PREFECT_HOME (own stores)."""
    root = tmp_path_factory.mktemp("server")
    home = (root / "prefect").resolve()
    assert not home.exists()
    try:
        with ThreadPoolExecutor(5) as pool:
            runs = list(pool.map(lambda i: _generate(home, root / f"store{i}", "--frames", "1"),
                                 range(5)))
        yield home, runs
    finally:
        srv.stop_server(home)
        for pid in _processes_of(home):  # anything left over, even after a failure
            os.kill(pid, signal.SIGKILL)


def test_five_concurrent_first_starts_all_finish_on_one_server(five_at_once):
    home, runs = five_at_once
    for run in runs:
        assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-3000:]
        assert "frames: 1 computed" in run.stdout
    state, healthy = srv.server_status(home)
    assert state is not None and healthy
    # exactly one run started the server (and migrated the database); the others reused it
    assert sum("started the local Prefect server" in r.stderr for r in runs) == 1
    assert _settled(home, {state.pid}).keys() == {state.pid}
    assert state.api_url.startswith("http://127.0.0.1:")


def _latest_flow_run_state(api_url: str) -> str:
    import httpx

    runs = httpx.post(f"{api_url}/flow_runs/filter", timeout=10,
                      json={"sort": "EXPECTED_START_TIME_DESC", "limit": 1}).json()
    return runs[0]["state"]["type"]


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_a_killed_generate_leaves_no_process_but_the_managed_server(five_at_once, tmp_path, sig):
    home, _ = five_at_once
    server, _ = srv.ensure_server(home)
    store, opd = tmp_path / "store", tmp_path / "openpcdet"
    frames = 24
    proc = subprocess.Popen([*CLI, "generate", *TINY, "--frames", str(frames), "--out",
                             str(store), "--export-openpcdet", str(opd)], cwd=REPO,
                            env=_env(home), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:  # kill it inside the flow: after its world, before its frames are done
        deadline = time.monotonic() + 120
        while not list(store.glob("world_specs/*.parquet")) and proc.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        os.kill(proc.pid, sig)  # the run's process only, as a scheduler or `kill PID` does
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == -sig, f"the run ended before it was killed: {err[-3000:]}"
    # it stopped there: a SIGTERM'd run reports Crashed and goes without finishing its world
    # (Prefect's own thread pool waited for all 24 frames)
    assert len(list(store.glob("dataset_frames/*.parquet"))) < frames
    if sig == signal.SIGTERM:
        assert _latest_flow_run_state(server.api_url) == "CRASHED"
    left = _settled(home, {server.pid})
    assert left.keys() == {server.pid}, left
    assert srv.server_status(home) == (server, True)  # the next run reuses it


def test_server_stop_leaves_no_process_and_a_dead_server_is_replaced(five_at_once, tmp_path):
    home, _ = five_at_once
    cli = ["server", "status", "--home", str(home)]
    runner = CliRunner()
    res = runner.invoke(app, cli)
    assert res.exit_code == 0 and "running: http://127.0.0.1:" in res.output, res.output
    # a server that died between commands (its record is stale) is replaced by the next one
    old, _ = srv.server_status(home)
    os.kill(old.pid, signal.SIGKILL)
    _settled(home, set())
    run = _generate(home, tmp_path / "store", "--frames", "1")
    assert run.returncode == 0, run.stderr[-3000:]
    new, healthy = srv.server_status(home)
    assert healthy and new.pid != old.pid and "started the local Prefect server" in run.stderr
    res = runner.invoke(app, ["server", "stop", "--home", str(home)])
    assert res.exit_code == 0 and f"pid {new.pid}" in res.output, res.output
    assert _settled(home, set()) == {}
    assert not (home / srv.STATE_FILE).exists()
    res = runner.invoke(app, cli)
    assert res.exit_code == 1 and "no managed Prefect server" in res.output


# --- no server started below ------------------------------------------------------------


def test_a_stale_record_never_names_another_process(tmp_path):
    """A recorded pid that now belongs to an unrelated process is not 'the server': status
    says none runs and stop does not signal it."""
    other = subprocess.Popen(["sleep", "30"])
    try:
        home = tmp_path / "prefect"
        home.mkdir()
        record = {"pid": other.pid, "port": 1, "prefect_version": "3.8.8",
                  "started_at": time.time(), "home": str(home)}
        (home / srv.STATE_FILE).write_text(json.dumps(record))
        assert srv.server_status(home) == (None, False)
        assert srv.stop_server(home) is None
        assert other.poll() is None and not (home / srv.STATE_FILE).exists()
    finally:
        other.kill()
        other.wait()


def test_the_users_own_prefect_settings_win(tmp_path, monkeypatch):
    """No server is started (nor PREFECT_API_URL changed) when the user configured one, chose
    the ephemeral mode, or Prefect is already imported; a bad mode exits 2."""
    import typer

    started = []
    monkeypatch.setattr(srv, "ensure_server", lambda *a, **k: started.append(a))
    monkeypatch.setenv("PREFECT_HOME", str(tmp_path))
    monkeypatch.setenv(srv.MODE_ENV, "managed")
    monkeypatch.setenv("PREFECT_API_URL", "http://127.0.0.1:4200/api")
    srv.use_managed_server()
    monkeypatch.delenv("PREFECT_API_URL")
    monkeypatch.setenv(srv.MODE_ENV, "ephemeral")
    # Prefect's temporary server gets the managed one's start-up budget (its own is 20 s,
    # which a fresh database outlasted on slow cores); a user's own value is kept
    timeout = "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS"
    monkeypatch.delenv(timeout, raising=False)
    srv.use_managed_server()
    assert os.environ[timeout] == str(int(srv.STARTUP_TIMEOUT_S))
    monkeypatch.setenv(timeout, "7")
    srv.use_managed_server()
    assert os.environ[timeout] == "7"
    monkeypatch.setenv(srv.MODE_ENV, "managed")
    (tmp_path / "profiles.toml").write_text(
        'active = "mine"\n[profiles.mine]\nPREFECT_API_URL = "http://10.0.0.1:4200/api"\n')
    monkeypatch.delitem(sys.modules, "prefect", raising=False)
    srv.use_managed_server()
    (tmp_path / "profiles.toml").unlink()
    monkeypatch.setitem(sys.modules, "prefect", sys)  # "already imported"
    srv.use_managed_server()
    assert started == [] and "PREFECT_API_URL" not in os.environ
    monkeypatch.setenv(srv.MODE_ENV, "sometimes")
    with pytest.raises(typer.Exit) as info:
        srv.use_managed_server()
    assert info.value.exit_code == 2


def test_a_copied_or_lost_record_never_forks_the_server(tmp_path):
    """Issue #33, probe 5: a PREFECT_HOME copied with its record does not reach (or stop) the
    original's server; a record with the right pid and port but another token is not the
    server; a record deleted or truncated while the server runs is recovered from the live
    process, and no second server starts on the database."""
    import shutil

    home, copy = (tmp_path / "a").resolve(), (tmp_path / "b").resolve()
    try:
        state, started = srv.ensure_server(home)
        assert started and len(state.token) == 32
        assert srv._identity(state.port)["token"] == state.token
        shutil.copytree(home, copy, ignore=shutil.ignore_patterns("*.lock"))
        assert srv.read_state(copy) is None                 # names /a: not the copy's record
        assert srv.server_status(copy) == (None, False)
        assert srv.stop_server(copy) is None
        assert srv.server_status(home) == (state, True)
        forged = {**json.loads((home / srv.STATE_FILE).read_text()), "home": str(copy)}
        (copy / srv.STATE_FILE).write_text(json.dumps(forged))
        assert srv.server_status(copy) == (None, False)     # runs in /a, not in /b
        assert srv.stop_server(copy) is None
        wrong = {**json.loads((home / srv.STATE_FILE).read_text()), "token": "0" * 32}
        (home / srv.STATE_FILE).write_text(json.dumps(wrong))
        assert srv.read_state(home).token == "0" * 32
        found, healthy = srv.server_status(home)             # found as the live server
        assert healthy and (found.pid, found.port, found.token) == (state.pid, state.port,
                                                                    state.token)
        for damage in ("wrong token", "truncate", "delete"):
            if damage == "truncate":
                (home / srv.STATE_FILE).write_text('{"pid": ')
            elif damage == "delete":
                (home / srv.STATE_FILE).unlink()
            else:
                (home / srv.STATE_FILE).write_text(json.dumps(wrong))
            again, started = srv.ensure_server(home)
            assert not started and again.pid == state.pid and again.token == state.token
            assert srv.read_state(home) == again              # the record is written back
        (home / srv.STATE_FILE).unlink()
        stopped = srv.stop_server(home)                      # a lost record still stops it
        assert stopped is not None and stopped.pid == state.pid
        assert _settled(home, set()) == {}
    finally:
        for h in (home, copy):
            srv.stop_server(h)
            for pid in _processes_of(h):
                os.kill(pid, signal.SIGKILL)


def test_a_server_killed_mid_run_lets_the_run_finish_without_it(tmp_path):
    """Issue #33, probe 5: the managed server dies (SIGKILL) while `generate` runs; the run
    finishes its work without Prefect, writes its export (the same frames as a run that never
    used Prefect) and exits 0 with one line saying the server went away — no tracebacks, no
    minutes of retries at exit."""
    home, store = (tmp_path / "prefect").resolve(), tmp_path / "store"
    args = ["generate", *TINY, "--worlds", "6", "--frames", "2", "--out", str(store),
            "--export-openpcdet", str(tmp_path / "exp")]
    try:
        state, _ = srv.ensure_server(home)
        run = subprocess.Popen([*CLI, *args], cwd=REPO, env=_env(home), text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 240
        while not list((store / "dataset_frames").glob("*.parquet")):
            assert run.poll() is None and time.monotonic() < deadline, run.communicate()
            time.sleep(0.2)
        os.kill(state.pid, signal.SIGKILL)
        t_kill = time.monotonic()
        out, err = run.communicate(timeout=400)
        assert run.returncode == 0, out[-2000:] + err[-3000:]
        assert time.monotonic() - t_kill < 180
        assert err.count("went away during the run") == 1, err[-3000:]
        assert "Traceback" not in out + err and "EventsWorker" not in err
        assert "frames: " in out and " 0 failed" in out
        plain = subprocess.run([*CLI, *args[:-4], "--out", str(tmp_path / "plain"),
                                "--export-openpcdet", str(tmp_path / "exp_plain"),
                                "--no-prefect"], cwd=REPO, env=_env(home), capture_output=True,
                               text=True, timeout=400)
        assert plain.returncode == 0, plain.stderr[-2000:]
        ours = sorted((tmp_path / "exp" / "points").glob("*.npy"))
        assert len(ours) == 12
        for f in ours:
            assert f.read_bytes() == (tmp_path / "exp_plain" / "points" / f.name).read_bytes()
    finally:
        srv.stop_server(home)
        for pid in _processes_of(home):
            os.kill(pid, signal.SIGKILL)


def test_the_prefect_cli_talks_to_the_managed_server(tmp_path):
    """Issue #34, item 3: in the same PREFECT_HOME, `prefect server status` finds the managed
    server and `prefect flow-run ls` lists its runs instead of starting a second server on the
    database (a profile sim2radar-managed, active); stopping it restores Prefect's default; a
    user's own active profile with its PREFECT_API_URL is never replaced."""
    import tomllib

    home = (tmp_path / "prefect").resolve()
    prefect = [sys.executable, "-m", "prefect"]
    try:
        state, _ = srv.ensure_server(home)
        doc = tomllib.loads((home / "profiles.toml").read_text())
        assert doc["active"] == srv.MANAGED_PROFILE
        assert doc["profiles"][srv.MANAGED_PROFILE] == {"PREFECT_API_URL": state.api_url}
        env = _env(home)
        status = subprocess.run([*prefect, "server", "status"], env=env, capture_output=True,
                                text=True, timeout=120)
        assert status.returncode == 0, status.stdout + status.stderr
        assert str(state.port) in status.stdout + status.stderr
        runs = subprocess.run([*prefect, "flow-run", "ls"], env=env, capture_output=True,
                              text=True, timeout=120)
        assert runs.returncode == 0, runs.stdout + runs.stderr
        assert set(_processes_of(home)) == {state.pid}           # no second server
    finally:
        srv.stop_server(home)
        for pid in _processes_of(home):
            os.kill(pid, signal.SIGKILL)
    doc = tomllib.loads((home / "profiles.toml").read_text())
    assert doc["active"] == "ephemeral" and srv.MANAGED_PROFILE not in doc.get("profiles", {})
    (home / "profiles.toml").write_text('active = "mine"\n\n[profiles.mine]\n'
                                        'PREFECT_API_URL = "http://127.0.0.1:4200/api"\n'
                                        'PREFECT_LOGGING_LEVEL = "INFO"\n')
    srv.point_profile_at(home, srv.ServerState(1, 5, "3.8.8", 0.0, str(home), "t"))
    doc = tomllib.loads((home / "profiles.toml").read_text())
    assert doc["active"] == "mine" and set(doc["profiles"]) == {"mine"}


def test_cli_runs_send_info_logs_to_the_ui_while_the_console_stays_quiet(tmp_path):
    """Issue #34, item 2: the CLI's quiet console used to silence the API log handler too (no
    run logs in the UI); now INFO lines — Prefect's and sim2radar's own — reach the server and
    the console shows none of them."""
    home = (tmp_path / "prefect").resolve()
    try:
        env = {k: v for k, v in _env(home).items() if not k.startswith("PREFECT_LOGGING")}
        run = subprocess.run([*CLI, "generate", *TINY, "--frames", "1", "--out",
                              str(tmp_path / "store")], cwd=REPO, env=env, capture_output=True,
                             text=True, timeout=300)
        assert run.returncode == 0, run.stderr[-3000:]
        assert "INFO" not in run.stdout + run.stderr
        state, _ = srv.server_status(home)
        req = urllib.request.Request(state.api_url + "/logs/filter",
                                     data=json.dumps({"limit": 200}).encode(),
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=30) as resp:
            logs = json.loads(resp.read())
        names = {(log["level"], log["name"].split(".")[0]) for log in logs}
        assert (20, "prefect") in names and (20, "sim2radar") in names, names
        assert all(log["flow_run_id"] for log in logs)
    finally:
        srv.stop_server(home)
        for pid in _processes_of(home):
            os.kill(pid, signal.SIGKILL)
