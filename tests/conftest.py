"""Shared test configuration: CPU by default, Prefect state kept inside the test tmp dir."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

import pytest

# Keep Prefect's state out of ~ (and out of the Makefile's .prefect) and make it quiet; tests
# never need a running server. One PREFECT_HOME per test process: `make test` runs two
# (pytest-xdist), and the CLI runs each starts would otherwise share one SQLite database.
_PREFECT_HOME = tempfile.mkdtemp(prefix="sim2radar-test-prefect-")
os.environ["PREFECT_HOME"] = _PREFECT_HOME
atexit.register(shutil.rmtree, _PREFECT_HOME, ignore_errors=True)
os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")
# CLI runs in tests keep Prefect's per-process temporary API instead of leaving a managed
# server per temporary PREFECT_HOME (tests/cli/test_server.py tests the managed one).
os.environ.setdefault("SIM2RADAR_PREFECT_SERVER", "ephemeral")


def pytest_addoption(parser):
    parser.addoption(
        "--reverse-within-modules", action="store_true",
        help="run each module's tests in reverse order (module fixtures are shared, and "
             "`--dist worksteal` may run a module's later tests first: this finds a test "
             "that changes what an earlier one reads)")


def pytest_collection_modifyitems(config, items):
    from itertools import groupby

    from sim2radar.hardware import has_cuda

    if config.getoption("--reverse-within-modules"):
        items[:] = [it for _, group in groupby(items, key=lambda it: it.nodeid.split("::")[0])
                    for it in reversed(list(group))]
    if has_cuda():
        return
    skip = pytest.mark.skip(reason="needs a CUDA GPU")
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def prefect_server():
    """One temporary Prefect API for the whole test process, for the tests that run flows in
    this process (its state in the process's temporary PREFECT_HOME)."""
    from prefect.settings import PREFECT_HOME, temporary_settings
    from prefect.testing.utilities import prefect_test_harness

    with temporary_settings(updates={PREFECT_HOME: _PREFECT_HOME}), prefect_test_harness(
        server_startup_timeout=120
    ):
        yield


@pytest.fixture
def unwritable_dir(tmp_path, monkeypatch):
    """A folder in which nothing can be created (mode 0o555). Root ignores permission bits, so
    when the process can still write there, creating files or folders inside it is refused
    in this process (``open``/``os.open``/``os.mkdir`` raise ``PermissionError``)."""
    import errno

    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        (folder / "probe").touch()
    except PermissionError:
        pass
    else:
        (folder / "probe").unlink()
        import builtins

        real_open, real_mkdir, real_builtin_open = os.open, os.mkdir, builtins.open
        inside = str(folder) + os.sep

        def refuse(path):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(path))

        def open_(path, flags, *args, **kwargs):
            writing = flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT)
            if writing and os.fspath(path).startswith(inside):
                refuse(path)
            return real_open(path, flags, *args, **kwargs)

        def mkdir_(path, *args, **kwargs):
            if os.fspath(path).startswith(inside):
                refuse(path)
            return real_mkdir(path, *args, **kwargs)

        def builtin_open(file, mode="r", *args, **kwargs):
            if isinstance(file, str | os.PathLike) and os.fspath(file).startswith(inside) \
                    and any(c in mode for c in "wax+"):
                refuse(file)
            return real_builtin_open(file, mode, *args, **kwargs)

        monkeypatch.setattr(os, "open", open_)
        monkeypatch.setattr(builtins, "open", builtin_open)
        monkeypatch.setattr(os, "mkdir", mkdir_)
    yield folder
    folder.chmod(0o755)
