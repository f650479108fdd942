"""pymeshlab from worker threads (Prefect task runners): decimation processes shared by the
threads, or one dedicated thread; neither may crash the process at exit."""

from __future__ import annotations

import inspect
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

from sim2radar.reconstruct import meshing
from sim2radar.reconstruct.meshlab_process import decimate


def _grid(n: int = 20):
    xs, ys = np.meshgrid(np.arange(n), np.arange(n))
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], 1).astype(np.float32)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (i * n + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + n], 1), np.stack([a + 1, a + n + 1, a + n], 1)])
    return v, f.astype(np.int32)


#: :func:`_grid` for the scripts the tests run in a process of their own
_GRID_SOURCE = "import numpy as np\n" + inspect.getsource(_grid)


def _wavy_grid(n: int, seed: int):
    """An n x n grid with a random height field: decimation has choices to make."""
    v, f = _grid(n)
    v[:, 2] = np.random.default_rng(seed).normal(0.0, 0.3, len(v)).astype(np.float32)
    return v, f


def test_decimation_processes_give_this_process_s_bits(monkeypatch):
    meshes = [_wavy_grid(n, seed) for seed, n in enumerate((30, 45, 60))]
    here = [decimate(v, f, 200) for v, f in meshes]
    monkeypatch.setenv(meshing.MESHLAB_PROCESSES_ENV, "2")
    started = [meshing._start_simplify(v, f, 200) for v, f in meshes]   # side by side
    for (v0, f0), job in zip(here, started, strict=True):
        v1, f1 = job.result()
        assert v1.dtype == np.float32 and f1.dtype == np.int32
        assert 0 < len(f1) <= 220
        np.testing.assert_array_equal(v1, v0)
        np.testing.assert_array_equal(f1, f0)
    monkeypatch.setenv(meshing.MESHLAB_PROCESSES_ENV, "0")          # the dedicated thread
    v2, f2 = meshing.simplify_mesh(*meshes[0], 200)
    np.testing.assert_array_equal(f2, here[0][1])


def test_the_process_count_setting_is_checked(monkeypatch):
    monkeypatch.setenv(meshing.MESHLAB_PROCESSES_ENV, "two")
    with pytest.raises(ValueError, match="SIM2RADAR_MESHLAB_PROCESSES must be an integer >= 0"):
        meshing.simplify_mesh(*_grid(), 50)
    monkeypatch.setenv(meshing.MESHLAB_PROCESSES_ENV, "")
    assert 1 <= meshing.meshlab_processes() <= meshing.MAX_DEFAULT_MESHLAB_PROCESSES


def test_a_decimation_process_that_dies_fails_its_mesh_and_the_next_mesh_gets_a_new_one(
        monkeypatch):
    monkeypatch.setenv(meshing.MESHLAB_PROCESSES_ENV, "1")
    v, f = _grid()
    meshing.simplify_mesh(v, f, 50)
    pool = meshing._decimation_pool(1)
    first = pool._workers[0].proc
    first.kill()                                     # died between two meshes: restarted
    first.wait()
    assert len(meshing.simplify_mesh(v, f, 50)[1]) <= 60
    second = pool._workers[0].proc
    assert second.pid != first.pid
    big = _wavy_grid(400, 0)                         # ~320k faces: seconds of work
    job = meshing._start_simplify(*big, 100)
    time.sleep(0.5)
    os.kill(second.pid, signal.SIGKILL)              # dies while decimating
    with pytest.raises(RuntimeError, match=r"decimation process \(pid \d+\) ended .* 318402 "
                                           r"faces.*SIM2RADAR_MESHLAB_PROCESSES=0"):
        job.result()
    assert len(meshing.simplify_mesh(v, f, 50)[1]) <= 60
    assert pool._workers[0].proc.pid not in (first.pid, second.pid)


def test_an_error_in_a_decimation_process_reaches_the_caller(monkeypatch):
    monkeypatch.setenv(meshing.MESHLAB_PROCESSES_ENV, "1")
    v, f = _grid()
    with pytest.raises(Exception, match="bad vertex index 405"):   # pymeshlab's own error
        meshing.simplify_mesh(v, np.vstack([f, [[0, 1, len(v) + 5]]]).astype(np.int32), 50)
    assert len(meshing.simplify_mesh(v, f, 50)[1]) <= 60   # the same process goes on


def test_decimation_runs_on_the_dedicated_thread_and_propagates_errors(monkeypatch):
    monkeypatch.setenv(meshing.MESHLAB_PROCESSES_ENV, "0")
    seen = []
    v, f = _grid()
    out = meshing._on_meshlab_thread(lambda: seen.append(threading.current_thread().name) or 1)
    assert out == 1 and seen == ["sim2radar-pymeshlab"]
    sv, sf = meshing.simplify_mesh(v, f, 50)
    assert 0 < len(sf) <= 60 and sv.dtype == np.float32
    try:
        meshing._on_meshlab_thread(lambda: 1 / 0)
    except ZeroDivisionError:
        pass
    else:  # pragma: no cover
        raise AssertionError("the worker's exception must reach the caller")


def test_reconstruction_in_short_lived_threads_exits_cleanly(tmp_path):
    # Regression: before pymeshlab calls moved to one long-lived thread, this aborted at
    # interpreter exit in about half of the runs ("malloc_consolidate()", status 134).
    script = textwrap.dedent(
        """
        import threading
        from sim2radar.reconstruct import FrameInput, reconstruct
        from sim2radar.reconstruct.synthetic import corridor_frame
        sf = corridor_frame(160, 120)
        fi = FrameInput(sf.rgb, sf.intrinsics, sf.lidar_points)
        for _ in range(6):
            t = threading.Thread(target=reconstruct, args=(fi,))
            t.start(); t.join()
        print("done")
        """
    )
    for _ in range(2):
        proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              timeout=300, cwd=str(tmp_path.parent))
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert "done" in proc.stdout


def test_decimation_processes_end_with_their_parent(tmp_path):
    script = _GRID_SOURCE + textwrap.dedent(
        """
        import os, signal, sys
        import numpy as np
        from sim2radar.reconstruct import meshing
        os.environ[meshing.MESHLAB_PROCESSES_ENV] = "2"
        v, f = _grid(30)
        jobs = [meshing._start_simplify(v, f, 50) for _ in range(4)]
        [j.result() for j in jobs]
        pids = [w.proc.pid for w in meshing._decimation_pool(2)._workers]
        print(" ".join(map(str, pids)), flush=True)
        if sys.argv[1] == "kill":
            os.kill(os.getpid(), signal.SIGKILL)     # no clean-up at all
        """
    )
    for how in ("exit", "kill"):
        proc = subprocess.run([sys.executable, "-c", script, how], capture_output=True,
                              text=True, timeout=120, cwd=str(tmp_path))
        assert proc.returncode == (0 if how == "exit" else -signal.SIGKILL), proc.stderr[-2000:]
        pids = [int(p) for p in proc.stdout.split()]
        assert len(pids) == 2 and os.getpid() not in pids
        deadline = time.monotonic() + 10.0
        while any(_alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not any(_alive(p) for p in pids), f"decimation processes left after {how}"


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead but not yet reaped by init, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_forked_child_decimates_with_processes_of_its_own(tmp_path):
    # a DataLoader worker forked from a process that decimated must not write into its
    # parent's decimation processes' pipes (their answers would go to whoever reads first)
    script = _GRID_SOURCE + textwrap.dedent(
        """
        import os, warnings
        import numpy as np
        from sim2radar.reconstruct import meshing
        warnings.simplefilter("ignore", DeprecationWarning)   # fork() with threads (3.12+)
        os.environ[meshing.MESHLAB_PROCESSES_ENV] = "1"
        v, f = _grid(20)
        meshing.simplify_mesh(v, f, 50)
        mine = meshing._decimation_pool(1)._workers[0].proc.pid
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            try:
                faces = len(meshing.simplify_mesh(v, f, 50)[1])
                theirs = meshing._decimation_pool(1)._workers[0].proc.pid
                os.write(w, f"{faces} {theirs}".encode())
            finally:
                os._exit(0)
        os.close(w)
        faces, theirs = map(int, os.read(r, 100).split())
        os.waitpid(pid, 0)
        assert faces <= 60 and theirs != mine, (faces, theirs, mine)
        assert len(meshing.simplify_mesh(v, f, 50)[1]) <= 60   # the parent's still answer
        assert meshing._decimation_pool(1)._workers[0].proc.pid == mine
        print("ok")
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, cwd=str(tmp_path))
    assert proc.returncode == 0 and "ok" in proc.stdout, proc.stderr[-2000:]
