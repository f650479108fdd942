"""The shared Typer application that every command module registers on, and the helpers every
command shares (the store check, quiet consoles for recorded failures)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterable

import typer

app = typer.Typer(
    name="sim2radar",
    help="sim2radar: RGB -> material-labelled 3D scene -> simulated mmWave radar point clouds.",
    no_args_is_help=True,
    add_completion=False,
    # help texts are plain text: "[default 4]" and "[px]" are not Rich markup tags to drop
    rich_markup_mode=None,
)


@app.callback()
def _root() -> None:
    """sim2radar: RGB -> material-labelled 3D scene -> simulated mmWave radar point clouds."""


def exit_unless_writable(store: str, option: str = "--out") -> None:
    """Before any work: exit with status 2 and one line naming the path and the fix when the
    local store ``store`` cannot be written (:func:`storage.check_writable`; remote URIs are not
    probed)."""
    from sim2radar.storage import check_writable

    try:
        check_writable(store)
    except (ValueError, PermissionError) as exc:
        typer.secho(f"error: {option}: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None


def exit_unless_valid_dataset(dataset: str | None, option: str = "--dataset") -> None:
    """Before any work: exit with status 2 and one line when ``dataset`` cannot name a
    manifest (:func:`sim2radar.storage.manifest.check_dataset_name`: characters, length)."""
    from sim2radar.storage.manifest import check_dataset_name

    if dataset is None:
        return
    try:
        check_dataset_name(dataset)
    except ValueError as exc:
        typer.secho(f"error: {option}: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None


def exit_unless_writable_outputs(outputs: dict[str, object]) -> None:
    """:func:`exit_unless_writable` for each ``option -> folder`` given (None: not used), so a
    read-only export or picture folder stops the command before any work, not after it."""
    for option, path in outputs.items():
        if path is not None:
            exit_unless_writable(str(path), option)


def exit_unless_engine_fits(no_prefect: bool, workers: int, dask: str | None) -> None:
    """Before any work: exit with status 2 when ``--workers`` above 1 or ``--dask`` comes with
    ``--no-prefect``, whose plain loop runs one unit at a time in this process (it ran them
    that way without a word before)."""
    if not no_prefect or (workers <= 1 and not dask):
        return
    flag = "--dask" if dask else f"--workers {workers}"
    typer.secho(f"error: {flag} needs the Prefect engine; --no-prefect runs one unit at a time "
                f"in this process: drop --no-prefect"
                + ("" if dask else ", or use --workers 1"), fg="red", err=True)
    raise typer.Exit(2)


class _RecordedTaskFailures(logging.Filter):
    """Drops, from a console handler, the ERROR records Prefect's task engine writes when one
    of ``task_names`` fails (the exception with its traceback, then "Finished in state
    Failed"): the flow records that failure in the manifest and the command prints it in its
    summary, so on the console it is noise. The API handler still sends them to the UI."""

    def __init__(self, task_names: Iterable[str]) -> None:
        super().__init__()
        self.task_names = frozenset(task_names)

    def filter(self, record: logging.LogRecord) -> bool:
        return not (record.levelno >= logging.ERROR and record.name == "prefect.task_runs"
                    and getattr(record, "task_name", None) in self.task_names)


@contextlib.contextmanager
def quiet_recorded_failures(task_names: Iterable[str], verbose: bool = False):
    """While a flow runs: keep the tracebacks of failed ``task_names`` (per-scene tasks whose
    failure the flow records as ``failed`` in the manifest) off Prefect's console handlers.
    The task runs stay Failed in Prefect, with their tracebacks in the UI's logs; ``verbose``
    keeps them on the console too. Call after Prefect is imported (its logging is set up)."""
    if verbose:
        yield
        return
    from prefect.logging.handlers import PrefectConsoleHandler

    handlers = [h for h in logging.getLogger().handlers if isinstance(h, PrefectConsoleHandler)]
    quiet = _RecordedTaskFailures(task_names)
    for handler in handlers:
        handler.addFilter(quiet)
    try:
        yield
    finally:
        for handler in handlers:
            handler.removeFilter(quiet)


class ServerWatch:
    """Whether the Prefect API this process reports to stopped answering: a daemon thread
    asks ``{PREFECT_API_URL}/health`` every ``interval_s`` and sets :attr:`gone` after two
    refusals in a row (the server's process is gone), or after ``busy_s`` seconds of
    answers that only time out (a server too busy to answer within 2 s on a loaded machine is
    not gone: five runs starting together on 2 cores timed it out twice in a row). From then
    on Prefect's console output (its client's retries, the events worker's reconnects, the API
    log handler's errors) is dropped: the command says in one line that the server went away
    and finishes the run without it."""

    def __init__(self, api_url: str | None, interval_s: float = 1.0,
                 busy_s: float = 30.0) -> None:
        import threading

        self.api_url = api_url
        self.interval_s = interval_s
        self.busy_s = busy_s
        self.gone = threading.Event()
        self.why = ""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, name="sim2radar-server-watch",
                                        daemon=True)

    def _answers(self) -> str:
        import urllib.error
        import urllib.request

        try:
            with urllib.request.urlopen(f"{self.api_url}/health", timeout=2.0) as resp:
                return "" if resp.status == 200 else f"HTTP {resp.status}"
        except (OSError, urllib.error.URLError) as exc:
            return str(getattr(exc, "reason", exc))

    def _poll(self) -> None:
        import time

        misses, since = 0, 0.0
        while not self._stop.wait(self.interval_s):
            why = self._answers()
            if not why:
                misses = 0
                continue
            misses += 1
            since = since if misses > 1 else time.monotonic()
            busy = "timed out" in why.lower()
            if misses >= 2 and (not busy or time.monotonic() - since >= self.busy_s):
                self.why = why
                _silence_prefect()
                self.gone.set()
                return

    def say_gone(self) -> None:
        """The one line a command prints when the server went away."""
        typer.secho(f"warning: the Prefect server ({self.api_url}) went away during the run "
                    f"({self.why}); finishing it without Prefect", fg="yellow", err=True)

    def run(self, with_prefect, without_prefect, restart=lambda: None):
        """``with_prefect()``'s summary; when the server went away during it (whether it
        raised or returned), say so in one line, call ``restart()`` (e.g. reset a progress
        bar) and return ``without_prefect()``'s summary, marked ``prefect_server_went_away``
        (the work already done is cached, so the plain run only does the rest)."""
        summary = None
        try:
            summary = with_prefect()
        except Exception:
            if not self.gone.is_set():
                raise
        if not self.gone.is_set():
            return summary
        self.say_gone()
        restart()
        summary = without_prefect()
        summary["prefect_server_went_away"] = self.why or True
        return summary

    def __enter__(self) -> ServerWatch:
        if self.api_url:
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()


def _silence_prefect() -> None:
    """Drop Prefect's console records and API log handlers (the server is gone: every record
    would be another connection error)."""
    from prefect.logging.handlers import APILogHandler, PrefectConsoleHandler

    def not_prefect(record: logging.LogRecord) -> bool:
        return not record.name.startswith("prefect")

    loggers = [logging.getLogger()] + [lg for lg in list(logging.root.manager.loggerDict.values())
                                       if isinstance(lg, logging.Logger)]
    for lg in loggers:
        for h in list(lg.handlers):
            if isinstance(h, APILogHandler):
                lg.removeHandler(h)
            elif isinstance(h, PrefectConsoleHandler) or lg.name.startswith("prefect"):
                h.addFilter(not_prefect)  # e.g. prefect._internal's own stream handler
        if lg.name.startswith("prefect"):
            lg.setLevel(logging.CRITICAL + 1)


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print ``error: message`` in red on stderr; the ``typer.Exit(code)`` to raise."""
    typer.secho(f"error: {message}", fg="red", err=True)
    return typer.Exit(code)


def exit_now(code: int) -> None:
    """Exit with ``code`` without Prefect's exit handlers: after the server went away, its
    events worker would spend minutes retrying every event it still holds."""
    import os
    import sys

    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):  # a closed pipe: nothing more can be said
            stream.flush()
    os._exit(code)


def exit_status(code) -> int:
    """The process status ``sys.exit(code)`` would give: None is 0, an int itself, anything
    else is printed on stderr and gives 1."""
    import sys

    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1


def finish(code) -> None:
    """End the process with ``sys.exit(code)``'s status after Python's own shutdown steps (the
    non-daemon threads joined, the ``atexit`` handlers run: logging, Prefect, Dask, temporary
    folders; stdio flushed), but without tearing the native libraries down. Arrow's and other
    C++ thread pools can abort the finished process there, "terminate called without an active
    exception" (a worker still joinable when its static object is destroyed; apache/arrow
    #34314): a command that printed its result and exit code then ended with SIGABRT."""
    import atexit
    import ctypes
    import threading

    status = exit_status(code)
    threading._shutdown()      # what Py_FinalizeEx does first: thread atexits, join threads
    atexit._run_exitfuncs()    # then the atexit handlers (they run once: the list is cleared)
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)  # C stdio buffers (a native library's printf)
    exit_now(status)           # Python's stdio flushed, then os._exit


@contextlib.contextmanager
def export_folder_lock(folder):
    """Hold ``folder``'s writer lock while a command exports to it (None: nothing to lock);
    a folder another run is writing exits with status 2 and one line naming that run."""
    from sim2radar.fileio import FolderBusyError, writer_lock

    with contextlib.ExitStack() as held:
        if folder is not None:
            try:
                held.enter_context(writer_lock(folder, "export folder"))
            except FolderBusyError as exc:
                typer.secho(f"error: --export-openpcdet: {exc}", fg="red", err=True)
                raise typer.Exit(2) from None
        yield


def console():
    """The Rich console of a command's tables: the terminal's width, or — piped into a file or
    another program, where Rich would assume 80 columns and cut wide tables — 200 columns
    (``COLUMNS`` wins when set)."""
    import os
    import sys

    from rich.console import Console

    piped = not sys.stdout.isatty() and not os.environ.get("COLUMNS")
    return Console(width=200 if piped else None)
