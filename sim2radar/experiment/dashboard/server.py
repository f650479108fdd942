"""The live dashboard: one sweep folder's page on a loopback address: ``/``, ``/data.json`` and
``/run/<run id>`` (the page with that run's own view open).

    serve_dashboard(folder, port=0)          start serving; returns the DashboardServer
    allowed_host(header, bind_host)          the Host-header check (DNS rebinding)

The page is :func:`~.page.render_html` with ``live=True``; it polls ``/data.json``
(:func:`~.data.dashboard_data` of the folder as it is now) and re-renders in place. ``/run/<id>``
serves the same page, which opens the run its address names (a run's id is its ``run_key``,
:func:`~.runs.run_ids`); an id the sweep does not have (yet) is 404.
"""

from __future__ import annotations

import ipaddress
import json
import os
import threading
import urllib.parse
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

from sim2radar.experiment.dashboard.data import FILES, dashboard_data, error_data, load_sweep
from sim2radar.experiment.dashboard.page import POLL_S, render_html
from sim2radar.experiment.folder import SweepFolder

__all__ = ["LOOPBACK_HOST_NAMES", "DashboardServer", "allowed_host", "serve_dashboard"]


def _check_loopback(host: str) -> None:
    if host == "localhost":
        return
    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if not loopback:
        raise ValueError(f"host {host!r}: the dashboard serves on a loopback address only "
                         "(127.0.0.1); to view it from another machine, forward the port "
                         "(ssh -L PORT:127.0.0.1:PORT)")


#: Host names a request to the live dashboard may carry (any port): a page of another site
#: that resolves its own name to 127.0.0.1 (DNS rebinding) sends its own name and is refused
LOOPBACK_HOST_NAMES = ("127.0.0.1", "localhost", "[::1]")


def _host_name(header: str | None) -> str | None:
    """The host of a ``Host`` header without its port, lower-cased (``[::1]`` keeps its
    brackets); None for a missing or malformed header."""
    if not header:
        return None
    value = header.strip().lower()
    if value.startswith("["):  # [v6]:port
        end = value.find("]")
        if end < 0:
            return None
        name, rest = value[:end + 1], value[end + 1:]
    else:
        name, sep, port = value.partition(":")
        rest = sep + port
    if rest and not (rest.startswith(":") and rest[1:].isdigit()):
        return None
    return name


def allowed_host(header: str | None, bind_host: str = "127.0.0.1") -> bool:
    """Whether a request's ``Host`` header names this loopback server: ``127.0.0.1``,
    ``localhost``, ``[::1]`` or the address it is bound to, with or without a port."""
    name = _host_name(header)
    bind = f"[{bind_host}]" if ":" in bind_host else bind_host
    return name is not None and name in (*LOOPBACK_HOST_NAMES, bind.lower())


class _HTTPServer(ThreadingHTTPServer):
    """A threading HTTP server for many browser tabs at once: a listen backlog of 128 (the
    default 5 left page loads unanswered under 200 concurrent clients), request threads that
    never hold up exit (daemon, not joined on close: Ctrl-C stops at once even while a request
    is in flight), and a client that goes away mid-answer is not an error."""

    request_queue_size = 128
    daemon_threads = True
    block_on_close = False

    def handle_error(self, request, client_address) -> None:
        import sys

        if isinstance(sys.exc_info()[1], ConnectionError):  # BrokenPipe, ConnectionReset
            return
        super().handle_error(request, client_address)


class DashboardServer:
    """The live dashboard of one sweep folder on a loopback address.

    ``/`` is the live page, ``/data.json`` :func:`dashboard_data` of the folder as it is now
    (re-read when one of its files changed; 503 with ``{"error"}`` while it cannot be read),
    ``/run/<id>`` the live page opened on that run's view (404 for an id the sweep has not
    got, or not yet); anything else is 404. A request whose ``Host`` header is not a loopback name
    (:func:`allowed_host`: ``127.0.0.1``, ``localhost`` or ``[::1]``, any port) gets 403 with a
    one-line body: a web page cannot read the dashboard by pointing its own domain at
    127.0.0.1 (DNS rebinding). Requests are served by a
    :class:`~http.server.ThreadingHTTPServer` in a daemon thread.

    Parameters
    ----------
    folder : the sweep folder.
    host : a loopback address (anything else is refused).
    port : TCP port; 0 picks a free one (see :attr:`port`).
    poll_s : seconds between the page's polls [s].
    """

    def __init__(self, folder: str | os.PathLike, host: str = "127.0.0.1", port: int = 0,
                 poll_s: float = POLL_S) -> None:
        _check_loopback(host)
        if not poll_s > 0:
            raise ValueError(f"poll_s must be > 0, got {poll_s}")
        self.folder = Path(folder)
        self.poll_s = float(poll_s)
        self._lock = threading.Lock()
        self._cache: tuple[Any, int, bytes] | None = None  # (signature, status, JSON body)
        self._last_good: dict[str, Any] | None = None
        self._run_ids: frozenset[str] = frozenset()  # the runs of the last readable state
        self._thread: threading.Thread | None = None
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802  (http.server's name)
                path = self.path.split("?", 1)[0]
                host = self.headers.get("Host")
                if not allowed_host(host, server.host):
                    why = (f"forbidden: Host {host!r} is not this loopback server; open "
                           f"http://127.0.0.1:{server.port}/\n")
                    self._send(403, "text/plain; charset=utf-8", why.encode("utf-8"))
                elif path in ("/", "/index.html"):
                    self._send(200, "text/html; charset=utf-8", server.page_bytes())
                elif path == "/data.json":
                    status, body = server.data_json()
                    self._send(status, "application/json", body)
                elif path.startswith("/run/") and len(path) > len("/run/"):
                    run = urllib.parse.unquote(path[len("/run/"):])
                    if server.has_run(run):
                        self._send(200, "text/html; charset=utf-8", server.page_bytes())
                    else:
                        why = (f"no run {run!r} in {server.folder} (not finished yet, or "
                               f"another sweep's); the runs are listed at {server.url}\n")
                        self._send(404, "text/plain; charset=utf-8", why.encode("utf-8"))
                else:
                    self._send(404, "text/plain; charset=utf-8", b"not found\n")

            def _send(self, status: int, ctype: str, body: bytes) -> None:
                try:
                    self.send_response(status)
                    self.send_header("Content-Type", ctype)
                    self.send_header("Content-Length", str(len(body)))
                    self.send_header("Cache-Control", "no-store")
                    self.end_headers()
                    self.wfile.write(body)
                except ConnectionError:  # the client closed the tab: nothing to answer
                    self.close_connection = True

            def log_message(self, format: str, *args: Any) -> None:  # noqa: A002
                pass  # quiet: the CLI prints the URL, not every poll

        self._page_cache: tuple[bytes, bytes] | None = None  # (data body, rendered page)
        self._render_lock = threading.Lock()
        self.renders = 0  # pages rendered (one per change of the folder, not per request)
        self._httpd = _HTTPServer((host, int(port)), Handler)

    @property
    def host(self) -> str:
        return str(self._httpd.server_address[0])

    @property
    def port(self) -> int:
        return int(self._httpd.server_address[1])

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def _signature(self) -> tuple:
        sig = []
        paths = [self.folder / f for f in FILES.values()]
        gap_dir = SweepFolder(self.folder).gap_dir
        if gap_dir.is_dir():
            paths += sorted(p for p in gap_dir.iterdir() if p.suffix == ".png")
        for p in paths:
            try:
                st = p.stat()
                sig.append((str(p), st.st_mtime_ns, st.st_size))
            except OSError:
                sig.append((str(p), None, None))
        return tuple(sig)

    def data_json(self) -> tuple[int, bytes]:
        """HTTP status and body of ``/data.json`` (re-read only when a file changed)."""
        with self._lock:
            sig = self._signature()
            if self._cache is not None and self._cache[0] == sig:
                return self._cache[1], self._cache[2]
            try:
                data = dashboard_data(load_sweep(self.folder, require_runs=False))
                status, doc = 200, data
                self._last_good = data
                self._run_ids = frozenset(data["runs"]["ids"])
            except ValueError as exc:
                status, doc = 503, {"error": str(exc)}
            body = json.dumps(doc, allow_nan=False, ensure_ascii=False).encode("utf-8")
            self._cache = (sig, status, body)
            return status, body

    def has_run(self, run_id: str) -> bool:
        """Whether the sweep (as it is now, or as last readable) has a run of this id."""
        self.data_json()
        return run_id in self._run_ids

    def page(self) -> str:
        """The live page with the folder's current data (or its last readable state)."""
        return self.page_bytes().decode("utf-8")

    def page_bytes(self) -> bytes:
        """:meth:`page` as UTF-8, rendered once per change of the folder (the page is
        megabytes: rendering it per request made 200 page loads take minutes)."""
        status, body = self.data_json()
        with self._render_lock:  # concurrent first loads wait for one render
            cached = self._page_cache
            if cached is not None and cached[0] == body:
                return cached[1]
            data = json.loads(body) if status == 200 else (
                self._last_good or error_data(self.folder, json.loads(body)["error"]))
            html = render_html(data, live=True, poll_s=self.poll_s,
                               data_url="/data.json").encode("utf-8")
            self._page_cache = (body, html)
            self.renders += 1
            return html

    def start(self) -> DashboardServer:
        """Serve in a daemon thread (no-op when already serving)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._httpd.serve_forever,
                                            kwargs={"poll_interval": 0.1},
                                            name=f"dashboard:{self.port}", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and close the socket (idempotent)."""
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join(timeout=5)
            self._thread = None
        self._httpd.server_close()

    def __enter__(self) -> DashboardServer:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()


def serve_dashboard(folder: str | os.PathLike, host: str = "127.0.0.1", port: int = 0, *,
                    poll_s: float = POLL_S) -> DashboardServer:
    """Serve the live dashboard of ``folder``; returns the started :class:`DashboardServer`
    (``.url``, ``.stop()``; also a context manager).

    The folder is checked first (:func:`load_sweep` with ``require_runs=False``: a sweep whose
    first run has not finished is shown with 0 runs), so a wrong path fails here, not in the
    browser.

    Raises
    ------
    SweepFolderError — the folder cannot be read; ValueError — ``host`` is not a loopback
    address; OSError — the port is taken.
    """
    load_sweep(folder, require_runs=False)
    return DashboardServer(folder, host, port, poll_s).start()
