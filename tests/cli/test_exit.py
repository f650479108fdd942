"""The CLI ends through :func:`sim2radar.cli._app.finish`: Python's own shutdown steps run (the
non-daemon threads finish, ``atexit`` handlers run, the output is flushed) and the exit status
is the command's, but the native libraries are not torn down: a C++ static destructor that
aborts, as the test registers one, is never called. Arrow's thread pools aborted a finished
``store verify`` with SIGABRT there ("terminate called without an active exception") in two of
the last three full test suites."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

PRELUDE = """
import atexit, concurrent.futures, sys, threading, time
from pathlib import Path
out = Path(sys.argv.pop(1))
atexit.register(lambda: (out / "atexit").write_text("ran"))
def late():
    time.sleep(0.3)
    (out / "thread").write_text("finished")
threading.Thread(target=late).start()          # non-daemon: the process waits for it
pool = concurrent.futures.ThreadPoolExecutor(2)  # never shut down: its idle workers must
pool.submit(lambda: None).result()              # be told to stop, not joined forever
print("x" * 100_000, end="")                    # a full pipe buffer's worth, flushed at exit
# a native library whose teardown aborts, registered as C++ registers a static's destructor
import ctypes
libc = ctypes.CDLL(None)
libc.__cxa_atexit(ctypes.cast(libc.abort, ctypes.c_void_p), None, None)
from sim2radar.cli import main
sys.argv[0] = "sim2radar"
main()
"""


@pytest.mark.parametrize(("args", "status"), [(["store", "verify", "{nothing}"], 2),
                                              (["--help"], 0), (["no-such-command"], 2)])
def test_the_cli_exits_with_the_commands_status_after_pythons_shutdown_steps(
        tmp_path, args, status):
    args = [a.format(nothing=tmp_path / "nothing") for a in args]
    proc = subprocess.run([sys.executable, "-c", PRELUDE, str(tmp_path), *args], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == status, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr and "terminate called" not in proc.stderr
    assert (tmp_path / "thread").read_text() == "finished"
    assert (tmp_path / "atexit").read_text() == "ran"
    assert proc.stdout.startswith("x" * 100_000)
    if status == 0:
        assert "Usage:" in proc.stdout
    else:
        assert proc.stderr.strip()  # the reason, on stderr


def test_an_exit_message_gives_status_one_and_is_printed():
    from sim2radar.cli._app import exit_status

    assert (exit_status(None), exit_status(0), exit_status(3)) == (0, 0, 3)
    assert exit_status("no store") == 1
