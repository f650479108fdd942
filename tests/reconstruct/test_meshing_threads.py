"""pymeshlab from worker threads (Prefect task runners) must not crash the process at exit."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import threading

import numpy as np

from sim2radar.reconstruct import meshing


def _grid(n: int = 20):
    xs, ys = np.meshgrid(np.arange(n), np.arange(n))
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], 1).astype(np.float32)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (i * n + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + n], 1), np.stack([a + 1, a + n + 1, a + n], 1)])
    return v, f.astype(np.int32)


def test_decimation_runs_on_the_dedicated_thread_and_propagates_errors():
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
