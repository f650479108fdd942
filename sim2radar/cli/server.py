"""The local Prefect API server the CLI's flows report to: one per ``PREFECT_HOME``.

Without ``PREFECT_API_URL``, a Prefect flow starts a temporary ("ephemeral") API server in a
child process: ~10 s on every command, a child that outlives a killed run (SIGKILL or SIGTERM
skip Prefect's ``atexit`` clean-up, so the uvicorn process is re-parented to PID 1), and two
runs starting at once on a fresh ``PREFECT_HOME`` can migrate the same SQLite database
together and crash. The CLI therefore keeps **one long-lived server per** ``PREFECT_HOME``
instead (:func:`ensure_server`), reused by every later command:

* the first command starts ``uvicorn prefect.server.api.server:create_app`` (what
  ``prefect server start`` runs: API, UI and services) on ``127.0.0.1`` and a free port, in
  its own session (a signal to the command's process group does not reach it), logging to
  ``PREFECT_HOME/sim2radar-server.log``, and records ``pid``/``port`` in
  ``PREFECT_HOME/sim2radar-server.json``;
* every command checks that record under an exclusive ``fcntl`` lock on
  ``PREFECT_HOME/sim2radar-server.lock``, so concurrent first starts start (and migrate) once
  and the others wait for that server; a record whose process died, or that is another
  process now, or another Prefect version, is replaced by a fresh server;
* ``sim2radar server stop`` (:func:`stop_server`) ends it; ``status`` / ``start`` report it.

One server per home, never forked. The record names its home and a random token; the server
runs Prefect's app behind :mod:`sim2radar.cli._prefect_app`, started in the home folder with
the token in its environment, and answers both on ``GET /sim2radar/server``. A record is
trusted only when its process runs that app in that home with that token and the server
answers them: a record copied with a ``PREFECT_HOME`` names another home and is ignored (the
copy gets its own server; ``server stop`` there stops nothing of the original's). A record
deleted or truncated while the server runs is recovered from the live process
(:func:`find_live_server`) instead of starting a second server on the same database.

A killed command therefore leaves no process of its own behind: the managed server is the only
one, and the next command reuses it. ``SIM2RADAR_PREFECT_SERVER=ephemeral`` restores
Prefect's own per-command server (and its problems); a ``PREFECT_API_URL`` in the environment
or in the active Prefect profile always wins (your own server). Only the CLI calls this: the
library and the flows never start servers, and nothing here imports Prefect.
"""

from __future__ import annotations

import contextlib
import http.client
import importlib.metadata
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import typer

from sim2radar.cli._app import app

__all__ = ["MANAGED_PROFILE", "MODE_ENV", "ServerError", "ServerState", "ensure_server",
           "find_live_server", "point_profile_at", "prefect_home", "read_state",
           "server_status", "stop_server", "use_managed_server"]

MODE_ENV = "SIM2RADAR_PREFECT_SERVER"  # "managed" (default) or "ephemeral"
STATE_FILE = "sim2radar-server.json"
LOCK_FILE = "sim2radar-server.lock"
LOG_FILE = "sim2radar-server.log"
HOST = "127.0.0.1"  # loopback only: the API has no authentication
STARTUP_TIMEOUT_S = 120.0  # a fresh database migrates first (~10 s idle, more on busy cores)
STOP_TIMEOUT_S = 15.0  # SIGTERM -> graceful uvicorn shutdown; SIGKILL after this
CLIENT_RETRIES = 3  # PREFECT_CLIENT_MAX_RETRIES for the managed server (unless set)
MANAGED_PROFILE = "sim2radar-managed"  # the Prefect profile naming the managed server
_APP = "sim2radar.cli._prefect_app:create_app"  # Prefect's app + GET /sim2radar/server
_LEGACY_APP = "prefect.server.api.server:create_app"  # servers started by sim2radar < 0.4


class ServerError(RuntimeError):
    """The managed server could not be started (the message ends with its log's tail)."""


@dataclass(frozen=True)
class ServerState:
    """The record of a managed server, as kept in ``PREFECT_HOME/sim2radar-server.json``.

    Attributes
    ----------
    pid : process id of the uvicorn process
    port : TCP port on 127.0.0.1
    prefect_version : the Prefect version that started it (another one restarts it)
    started_at : start time [s since the epoch]
    home : the ``PREFECT_HOME`` it serves
    token : a random token the server answers on ``GET /sim2radar/server`` with its home (""
        for a server started before tokens: trusted by its process alone)
    """

    pid: int
    port: int
    prefect_version: str
    started_at: float
    home: str
    token: str = ""

    @property
    def api_url(self) -> str:
        """What ``PREFECT_API_URL`` is set to (and the server's UI calls)."""
        return _api_url(self.port)

    @property
    def ui_url(self) -> str:
        return _ui_url(self.port)


def _ui_url(port: int) -> str:
    """The managed server's UI on ``port``."""
    return f"http://{HOST}:{int(port)}"


def _api_url(port: int) -> str:
    """The managed server's API on ``port``."""
    return f"{_ui_url(port)}/api"


# --- the record and its lock -------------------------------------------------------------


def prefect_home() -> Path:
    """``PREFECT_HOME`` as the CLI uses it: the environment's, else ``./.prefect``."""
    return Path(os.environ.get("PREFECT_HOME") or Path.cwd() / ".prefect").expanduser().resolve()


@contextlib.contextmanager
def _locked(home: Path) -> Iterator[None]:
    """Hold the exclusive lock of ``home``'s server record (released when a holder dies)."""
    import fcntl

    home.mkdir(parents=True, exist_ok=True)
    with open(home / LOCK_FILE, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def read_state(home: str | os.PathLike) -> ServerState | None:
    """The server record of ``home``, or None: no record, an unreadable one (truncated), or one
    that names another home (a ``PREFECT_HOME`` copied with its record: the copy gets its own
    server, and ``server stop`` there never stops the original's)."""
    try:
        doc = json.loads((Path(home) / STATE_FILE).read_text())
        state = ServerState(int(doc["pid"]), int(doc["port"]), str(doc["prefect_version"]),
                            float(doc["started_at"]), str(doc["home"]),
                            str(doc.get("token") or ""))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    if Path(state.home).expanduser().resolve() != Path(home).expanduser().resolve():
        return None
    return state


def _write_state(home: Path, state: ServerState) -> None:
    from sim2radar.fileio import write_json

    write_json(home / STATE_FILE, {**asdict(state), "api_url": state.api_url})


def _clear_state(home: Path) -> None:
    (home / STATE_FILE).unlink(missing_ok=True)


# --- the process ------------------------------------------------------------------------


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie child of ours is reaped and counts as dead)."""
    with contextlib.suppress(ChildProcessError, OSError):
        if os.waitpid(pid, os.WNOHANG)[0] == pid:
            return False
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False
    except OSError:  # no /proc (not Linux): ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True


def _process(pid: int) -> tuple[list[bytes], Path, dict[bytes, bytes]] | None:
    """``(command line, working folder, environment)`` of ``pid`` (Linux ``/proc``; None when
    it cannot be read)."""
    proc = Path(f"/proc/{pid}")
    try:
        args = (proc / "cmdline").read_bytes().split(b"\0")
        cwd = Path(os.readlink(proc / "cwd")).resolve()
        env = dict(item.split(b"=", 1) for item in (proc / "environ").read_bytes().split(b"\0")
                   if b"=" in item)
    except OSError:
        return None
    return args, cwd, env


def _is_ours(state: ServerState) -> bool:
    """Whether the record's process is still the server it started for its home: the pid
    runs our server app on the recorded port, in the recorded home, with the recorded token
    (not a reused pid, not the server of a home whose record was copied here)."""
    from sim2radar.cli._prefect_app import TOKEN_ENV

    if not _alive(state.pid):
        return False
    seen = _process(state.pid)
    if seen is None:
        return not Path("/proc").is_dir()  # no /proc: trust the pid and the health check
    args, cwd, env = seen
    app_ok = _APP.encode() in args or (not state.token and _LEGACY_APP.encode() in args)
    return (app_ok and str(state.port).encode() in args
            and cwd == Path(state.home).expanduser().resolve()
            and env.get(TOKEN_ENV.encode(), b"").decode() == state.token)


def _identity(port: int, timeout_s: float = 2.0) -> dict | None:
    """What the server on ``port`` answers on ``GET /sim2radar/server`` (None: no answer)."""
    from sim2radar.cli._prefect_app import IDENTITY_PATH

    conn = http.client.HTTPConnection(HOST, port, timeout=timeout_s)
    try:
        conn.request("GET", IDENTITY_PATH)
        resp = conn.getresponse()
        return json.loads(resp.read()) if resp.status == 200 else None
    except (OSError, http.client.HTTPException, ValueError):
        return None
    finally:
        conn.close()


def _answers_as(state: ServerState) -> bool:
    """Whether the server on the record's port is the recorded one: healthy and, for a
    server with a token, answering that token and home."""
    if not state.token:
        return _healthy(state.port)
    who = _identity(state.port)
    return (who is not None and who.get("token") == state.token
            and Path(str(who.get("home", ""))).resolve() == Path(state.home).resolve()
            and _healthy(state.port))


def _current(home: Path) -> ServerState | None:
    """``home``'s record when its process is the server; else the live server found without
    it (:func:`find_live_server`); else the record as it is (a dead server's, to replace), or
    None."""
    state = read_state(home)
    if state is not None and _is_ours(state):
        return state
    return find_live_server(home) or state


def find_live_server(home: str | os.PathLike) -> ServerState | None:
    """The managed server running for ``home`` found without its record (deleted or
    truncated while it ran): a process of this package's server app whose working folder is
    ``home`` (servers start there); its port, token and version come from its command line and
    environment (Linux ``/proc``; None elsewhere or when none runs)."""
    home = Path(home).expanduser().resolve()
    proc = Path("/proc")
    if not proc.is_dir():
        return None
    from sim2radar.cli._prefect_app import TOKEN_ENV

    for entry in proc.iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        seen = _process(int(entry.name))
        if seen is None:
            continue
        args, cwd, env = seen
        if (_APP.encode() not in args and _LEGACY_APP.encode() not in args) or cwd != home:
            continue
        try:
            port = int(args[args.index(b"--port") + 1])
        except (ValueError, IndexError):
            continue
        token = env.get(TOKEN_ENV.encode(), b"").decode()
        version = env.get(b"SIM2RADAR_PREFECT_VERSION", b"").decode() or _prefect_version()
        try:
            started = entry.stat().st_mtime
        except OSError:
            continue
        state = ServerState(int(entry.name), port, version, started, str(home), token)
        if _is_ours(state):
            return state
    return None


def _healthy(port: int, timeout_s: float = 2.0) -> bool:
    """``GET /api/health`` answers 200."""
    conn = http.client.HTTPConnection(HOST, port, timeout=timeout_s)
    try:
        conn.request("GET", "/api/health")
        return conn.getresponse().status == 200
    except (OSError, http.client.HTTPException):
        return False
    finally:
        conn.close()


def _wait_healthy(state: ServerState, timeout_s: float) -> bool:
    """Poll the health endpoint until it answers, the process dies or ``timeout_s`` passes."""
    deadline = time.monotonic() + timeout_s
    while True:
        if _answers_as(state):
            return True
        if not _is_ours(state) or time.monotonic() > deadline:
            return False
        time.sleep(0.1)


def _terminate(pid: int, timeout_s: float = STOP_TIMEOUT_S) -> None:
    """SIGTERM ``pid``, then SIGKILL if it has not exited within ``timeout_s``."""
    for sig, wait_s in ((signal.SIGTERM, timeout_s), (signal.SIGKILL, 5.0)):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, sig)
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            if not _alive(pid):
                return
            time.sleep(0.05)


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]


def _log_tail(home: Path, n_chars: int = 2000) -> str:
    try:
        return (home / LOG_FILE).read_text(errors="replace")[-n_chars:]
    except OSError:
        return ""


def _prefect_version() -> str:
    return importlib.metadata.version("prefect")


def _spawn(home: Path, port: int) -> ServerState:
    """Start a detached server on ``port`` (own session, stdin closed, output to the log).

    Its UI is told its own address: without ``PREFECT_UI_API_URL`` the server's
    ``/ui-settings`` answers Prefect's default ``http://127.0.0.1:4200/api`` and the UI on any
    other port shows "Oops. Something went wrong." (issue #24).
    """
    import secrets

    from sim2radar.cli._prefect_app import TOKEN_ENV

    token = secrets.token_hex(16)
    env = {**os.environ, "PREFECT_HOME": str(home), "PREFECT__SERVER_FINAL": "1",
           TOKEN_ENV: token, "SIM2RADAR_PREFECT_VERSION": _prefect_version()}
    env.pop("PREFECT_API_URL", None)
    # both names of the setting: Prefect reads PREFECT_SERVER_UI_API_URL first
    env.update({"PREFECT_UI_API_URL": _api_url(port), "PREFECT_SERVER_UI_API_URL": _api_url(port),
                "PREFECT_UI_URL": _ui_url(port)})
    env.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    args = [sys.executable, "-m", "uvicorn", "--factory", _APP, "--host", HOST,
            "--port", str(port), "--log-level", "warning", "--lifespan", "on"]
    with open(home / LOG_FILE, "a") as log:
        log.write(f"--- {time.strftime('%Y-%m-%d %H:%M:%S')} sim2radar: starting the Prefect "
                  f"server on {HOST}:{port}\n")
        log.flush()
        proc = subprocess.Popen(args, cwd=home, env=env, stdin=subprocess.DEVNULL, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True)
    # the server outlives this process on purpose; no Popen warning about it at exit
    proc.returncode = 0
    return ServerState(proc.pid, port, _prefect_version(), time.time(), str(home), token)


def ensure_server(home: str | os.PathLike | None = None, *,
                  timeout_s: float = STARTUP_TIMEOUT_S) -> tuple[ServerState, bool]:
    """The healthy managed server of ``home`` (default :func:`prefect_home`), started if needed.

    Returns ``(state, started)``: ``started`` is True when this call started it. Safe to call
    from many processes at once: one starts the server, the others wait for it.

    Raises
    ------
    ServerError when no server answered within ``timeout_s`` [s] (three tries on fresh ports).
    """
    home = Path(home).expanduser().resolve() if home is not None else prefect_home()
    with _locked(home):
        state = _current(home)
        if state is not None and read_state(home) != state:  # recovered: write it back
            _write_state(home, state)
            print(f"sim2radar: recovered the record of the running Prefect server "
                  f"(pid {state.pid}, port {state.port}) in {home}", file=sys.stderr)
        if state is not None:
            if state.prefect_version != _prefect_version() and _is_ours(state):
                _terminate(state.pid)  # started by another Prefect: its schema may differ
            elif _is_ours(state):
                # a live record: healthy at once, or still starting (a run killed while it
                # waited), or hung (replaced)
                age_s = max(0.0, time.time() - state.started_at)
                if _wait_healthy(state, max(5.0, timeout_s - age_s)):
                    point_profile_at(home, state)
                    return state, False
                _terminate(state.pid)
            _clear_state(home)
        for _ in range(3):
            state = _spawn(home, _free_port())
            _write_state(home, state)  # before waiting: a killed starter leaves a known pid
            if _wait_healthy(state, timeout_s):
                point_profile_at(home, state)
                return state, True
            _terminate(state.pid)  # exited (e.g. the port was taken meanwhile) or timed out
            _clear_state(home)
    raise ServerError(f"the local Prefect server in {home} did not start within {timeout_s:.0f} s; "
                      f"{home / LOG_FILE} ends with:\n{_log_tail(home)}")


def server_status(home: str | os.PathLike | None = None) -> tuple[ServerState | None, bool]:
    """``(state, healthy)`` of ``home``'s managed server; state None when none runs."""
    home = Path(home).expanduser().resolve() if home is not None else prefect_home()
    state = _current(home)
    if state is None or not _is_ours(state):
        return None, False
    return state, _answers_as(state)


def stop_server(home: str | os.PathLike | None = None, *,
                timeout_s: float = STOP_TIMEOUT_S) -> ServerState | None:
    """Stop ``home``'s managed server (SIGTERM, SIGKILL after ``timeout_s`` [s]) and remove
    its record; returns the stopped server's record, None when none ran."""
    home = Path(home).expanduser().resolve() if home is not None else prefect_home()
    if not home.is_dir():
        return None
    with _locked(home):  # waits for a server being started to be recorded
        state = _current(home)
        running = state is not None and _is_ours(state)
        if running:
            _terminate(state.pid, timeout_s)
        _clear_state(home)
        point_profile_at(home, None)
    return state if running else None


# --- the CLI's choice -------------------------------------------------------------------


def _profiles_path(home: Path) -> Path:
    return Path(os.environ.get("PREFECT_PROFILES_PATH") or home / "profiles.toml").expanduser()


def _read_profiles(home: Path) -> dict:
    import tomllib

    try:
        return tomllib.loads(_profiles_path(home).read_text())
    except (OSError, ValueError):
        return {}


def _profile_api_url(home: Path) -> str | None:
    """``PREFECT_API_URL`` of the active profile in Prefect's ``profiles.toml``, if any (not
    the one :func:`point_profile_at` wrote for the managed server: that one is ours)."""
    doc = _read_profiles(home)
    name = os.environ.get("PREFECT_PROFILE") or doc.get("active") or "ephemeral"
    if name == MANAGED_PROFILE:
        return None
    profile = (doc.get("profiles") or {}).get(name) or {}
    return profile.get("PREFECT_API_URL") or None


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(str(value))  # a TOML basic string (JSON escapes are TOML escapes)


def _write_profiles(home: Path, doc: dict) -> None:
    from sim2radar.fileio import atomic_write

    lines = [f"active = {_toml(doc['active'])}"] if doc.get("active") else []
    for name, table in (doc.get("profiles") or {}).items():
        lines += ["", f"[profiles.{json.dumps(name)}]"]
        lines += [f"{key} = {_toml(value)}" for key, value in (table or {}).items()]
    atomic_write(_profiles_path(home), ("\n".join(lines) + "\n").encode())


def point_profile_at(home: Path, state: ServerState | None) -> None:
    """Make the ``prefect`` CLI run with this ``PREFECT_HOME`` talk to the managed server:
    the profile ``sim2radar-managed`` in ``PREFECT_HOME/profiles.toml`` holds its
    ``PREFECT_API_URL`` and is active (``prefect server status`` finds it, ``prefect flow-run
    ls`` lists its runs instead of starting a second server on the database). A user's active
    profile with its own ``PREFECT_API_URL`` is left alone. ``state`` None (the server
    stopped): the profile is removed and Prefect's default (``ephemeral``) is active again.
    Other profiles are kept."""
    doc = _read_profiles(home)
    profiles = dict(doc.get("profiles") or {})
    active = doc.get("active")
    if state is None:
        if MANAGED_PROFILE not in profiles:
            return
        profiles.pop(MANAGED_PROFILE)
        new = {"active": "ephemeral" if active in (None, MANAGED_PROFILE) else active,
               "profiles": profiles}
    else:
        ours = {"PREFECT_API_URL": state.api_url}
        if active == MANAGED_PROFILE and profiles.get(MANAGED_PROFILE) == ours:
            return
        if active and active != MANAGED_PROFILE and (profiles.get(active) or {}).get(
                "PREFECT_API_URL"):
            return  # the user's own server
        profiles[MANAGED_PROFILE] = ours
        new = {"active": MANAGED_PROFILE, "profiles": profiles}
    try:
        _write_profiles(home, new)
    except OSError as exc:  # a read-only home: the CLI still works, the prefect CLI does not
        print(f"sim2radar: could not write {_profiles_path(home)} ({exc.strerror or exc}); "
              "the prefect CLI will not find the managed server", file=sys.stderr)


def use_managed_server() -> None:
    """Point this process's Prefect at the managed server of ``PREFECT_HOME`` (starting it if
    needed) by setting ``PREFECT_API_URL``; call before anything imports Prefect.

    Does nothing when ``PREFECT_API_URL`` is set (your own server, or an earlier call), when
    the active Prefect profile sets it, when ``SIM2RADAR_PREFECT_SERVER=ephemeral``, or when
    Prefect is already imported (its settings are fixed then: e.g. a test harness's server).
    A server that cannot start exits with status 1 and its log's tail.
    """
    mode = os.environ.get(MODE_ENV, "managed").strip().lower() or "managed"
    if mode not in ("managed", "ephemeral"):
        typer.secho(f"error: {MODE_ENV}={mode!r}: expected 'managed' or 'ephemeral'",
                    fg="red", err=True)
        raise typer.Exit(2)
    if mode == "ephemeral":
        # Prefect's temporary server gets the managed server's start-up budget, not Prefect's
        # 20 s: a fresh database migrates first, and on slow cores that took longer than 20 s
        # ("Timed out while attempting to connect to ephemeral Prefect API server")
        os.environ.setdefault("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS",
                              str(int(STARTUP_TIMEOUT_S)))
        return
    if os.environ.get("PREFECT_API_URL") or "prefect" in sys.modules:
        return
    home = prefect_home()
    if _profile_api_url(home):
        return
    try:
        state, started = ensure_server(home)
    except (ServerError, OSError) as exc:
        why = exc if isinstance(exc, ServerError) else f"PREFECT_HOME {home}: {exc.strerror}"
        typer.secho(f"error: {why}\n(`--no-prefect` runs without Prefect; "
                    f"{MODE_ENV}=ephemeral uses Prefect's temporary server)", fg="red", err=True)
        raise typer.Exit(1) from None
    os.environ["PREFECT_API_URL"] = state.api_url
    # a loopback server either answers or is gone: 3 retries (2 + 4 + 8 s), not Prefect's 5
    # (62 s per request) before a run notices and finishes without it
    os.environ.setdefault("PREFECT_CLIENT_MAX_RETRIES", str(CLIENT_RETRIES))
    if started:
        typer.secho(f"started the local Prefect server {state.ui_url} (pid {state.pid}, "
                    f"PREFECT_HOME {home}); later commands reuse it, `sim2radar server stop` "
                    f"stops it", dim=True, err=True)


# --- sim2radar server ... ---------------------------------------------------------------

server_app = typer.Typer(
    rich_markup_mode=None,
    help="The local Prefect server that commands report to (one per PREFECT_HOME).",
    no_args_is_help=True,
)
app.add_typer(server_app, name="server")

_HOME_HELP = "PREFECT_HOME of the server [default: $PREFECT_HOME, else ./.prefect]."


def _describe(state: ServerState) -> str:
    up_s = max(0.0, time.time() - state.started_at)
    return (f"{state.ui_url} (API {state.api_url}), pid {state.pid}, up {up_s / 60:.0f} min, "
            f"Prefect {state.prefect_version}, PREFECT_HOME {state.home}")


@server_app.command("start")
def start_cmd(home: Path | None = typer.Option(None, "--home", help=_HOME_HELP)) -> None:
    """Start the server now (commands otherwise start it on first use); print its address."""
    try:
        state, started = ensure_server(home)
    except (ServerError, OSError) as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"{'started' if started else 'running'}: {_describe(state)}")


@server_app.command("status")
def status_cmd(home: Path | None = typer.Option(None, "--home", help=_HOME_HELP)) -> None:
    """Print the server's address, pid and uptime. Exit status 1 when none runs."""
    state, healthy = server_status(home)
    if state is None:
        typer.echo(f"no managed Prefect server for {Path(home).resolve() if home else prefect_home()}")
        raise typer.Exit(1)
    typer.echo(f"{'running' if healthy else 'NOT ANSWERING'}: {_describe(state)}")
    if not healthy:
        raise typer.Exit(1)


@server_app.command("stop")
def stop_cmd(home: Path | None = typer.Option(None, "--home", help=_HOME_HELP)) -> None:
    """Stop the server (its flow-run history stays in PREFECT_HOME's database)."""
    state = stop_server(home)
    if state is None:
        typer.echo("no managed Prefect server was running")
    else:
        typer.echo(f"stopped the Prefect server on port {state.port} (pid {state.pid})")
