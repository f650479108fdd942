"""Cached rerun of ``sim2radar generate`` per geometry (issue #23): wall seconds of a rerun of a
finished dataset (nothing recomputed) as a user types it, each a new process, for
``--geometry reconstructed`` (the default) and ``--geometry ground_truth``, through Prefect
(the managed local server, already running) and with ``--no-prefect``::

    sim2radar generate --worlds 1 --frames 2 --width 160 --height 120 --spp 4 [--geometry G]

What a fully cached run imports and checks should not depend on the geometry; the goal is
<= 3 s for both. One managed Prefect server (:mod:`sim2radar.cli.server`) in a temporary
``PREFECT_HOME`` serves every run (what a user has after the first command: "server running"),
started before the first run (its start is timed) and stopped at the end. The first run of each
geometry (everything computed) is timed apart. The reruns are interleaved over the four
variants, ``SIM2RADAR_BENCH_CACHED_REPEATS`` rounds (5): median and min of the wall seconds,
median of the command's CPU seconds (user + system; less sensitive to a busy machine).

Also, per variant, one more rerun under ``python -X importtime``: its import seconds and which
heavy packages it imported (a cached rerun needs none of torch, mitsuba, drjit, cv2, onnxruntime,
pymeshlab, matplotlib, plotly); and ``SIM2RADAR_BENCH_CACHED_EPHEMERAL`` (1) reruns per geometry
with ``SIM2RADAR_PREFECT_SERVER=ephemeral`` (Prefect's own temporary server, started by every
command; ~10 s each; 0 skips them).

    python -m benchmarks cached_rerun
    SIM2RADAR_BENCH_CACHED_REPEATS=9 python -m benchmarks cached_rerun
"""

from __future__ import annotations

import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sim2radar.cli import server as srv

REPO = Path(__file__).resolve().parents[1]
REPEATS = int(os.environ.get("SIM2RADAR_BENCH_CACHED_REPEATS", "5"))
EPHEMERAL_REPEATS = int(os.environ.get("SIM2RADAR_BENCH_CACHED_EPHEMERAL", "1"))
RUN = ["--worlds", "1", "--frames", "2", "--width", "160", "--height", "120", "--spp", "4"]
CLI = [sys.executable, "-c", "from sim2radar.cli import main; main()"]
GEOMETRIES = ("reconstructed", "ground_truth")
GOAL_S = 3.0  # issue #23
#: Packages a cached rerun should not need (top-level names in ``-X importtime``'s output).
HEAVY = ("torch", "mitsuba", "drjit", "cv2", "onnxruntime", "pymeshlab", "matplotlib", "plotly",
         "shapely", "scipy.stats", "scipy.ndimage", "scipy.fft", "scipy.signal", "prefect")


def _env(home: Path, mode: str = "managed") -> dict[str, str]:
    env = {**os.environ, "PREFECT_HOME": str(home), srv.MODE_ENV: mode,
           "PREFECT_SERVER_ANALYTICS_ENABLED": "false"}
    env.pop("PREFECT_API_URL", None)
    return env


def _args(store: Path, geometry: str, prefect: bool) -> list[str]:
    return ["generate", *RUN, "--out", str(store), "--geometry", geometry,
            *([] if prefect else ["--no-prefect"])]


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process's finished children."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _run(args: list[str], env: dict[str, str], python_flags: tuple[str, ...] = (),
         cached: bool = True) -> tuple[float, float, str]:
    """(wall seconds, CPU seconds, stderr) of one CLI command in a new process; it must succeed
    and, if ``cached``, recompute no frame. The CPU seconds (the command's own, not the
    server's) depend less on what else the machine runs than the wall seconds."""
    cmd = [CLI[0], *python_flags, *CLI[1:], *args]
    c0, t0 = _cpu_s(), time.perf_counter()
    res = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
    wall_s, cpu_s = time.perf_counter() - t0, _cpu_s() - c0
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({res.returncode}):\n{res.stderr[-3000:]}")
    counts = re.search(r"frames:\s+(\d+)\s+computed,\s+(\d+)\s+cached,\s+(\d+)\s+failed",
                       " ".join(res.stdout.split()))
    if counts is None or int(counts.group(3)) or (cached and int(counts.group(1))):
        raise RuntimeError(f"{' '.join(args)} was not a {'cached ' if cached else ''}run "
                           f"without failures:\n{res.stdout[-2000:]}")
    return wall_s, cpu_s, res.stderr


def _imports(stderr: str) -> tuple[float, list[str]]:
    """(seconds spent importing, heavy packages imported) from ``-X importtime`` output."""
    total_us, names = 0, set()
    for line in stderr.splitlines():
        if not line.startswith("import time:") or "self [us]" in line:
            continue
        _, cumulative, name = line.split("|", 2)
        if not name.startswith("  "):  # top level: its cumulative time counts once
            total_us += int(cumulative)
        names.add(name.strip())
    return total_us / 1e6, [h for h in HEAVY
                            if any(n == h or n.startswith(h + ".") for n in names)]


def main() -> dict:
    variants = [(g, p) for p in (True, False) for g in GEOMETRIES]

    def label(geometry: str, prefect: bool) -> str:
        return f"{geometry}, {'Prefect (server running)' if prefect else '--no-prefect'}"

    rows: dict[str, list[float]] = {}
    cpu: dict[str, list[float]] = {}
    first: dict[str, float] = {}
    imports: dict[str, tuple[float, list[str]]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-cached-rerun-") as tmp:
        root = Path(tmp)
        home, store = root / "prefect-home", root / "store"
        env = _env(home)
        try:
            t0 = time.perf_counter()
            srv.ensure_server(home)
            server_start_s = time.perf_counter() - t0
            for g in GEOMETRIES:  # first runs: everything computed (the second reuses renders)
                first[g] = _run(_args(store, g, True), env, cached=False)[0]
            for _ in range(REPEATS):
                for g, p in variants:
                    wall_s, cpu_s, _ = _run(_args(store, g, p), env)
                    rows.setdefault(label(g, p), []).append(wall_s)
                    cpu.setdefault(label(g, p), []).append(cpu_s)
            for g, p in variants:
                imports[label(g, p)] = _imports(
                    _run(_args(store, g, p), env, ("-X", "importtime"))[2])
            for _ in range(EPHEMERAL_REPEATS):
                for g in GEOMETRIES:
                    name = f"{g}, Prefect (ephemeral server)"
                    wall_s, cpu_s, _ = _run(_args(store, g, True),
                                            _env(root / "eph-home", "ephemeral"))
                    rows.setdefault(name, []).append(wall_s)
                    cpu.setdefault(name, []).append(cpu_s)
        finally:
            srv.stop_server(home)
    print(f"generate {' '.join(RUN)} [--geometry G] [--no-prefect]; each a new process; "
          f"{REPEATS} round(s); load average (1 min) at the end {os.getloadavg()[0]:.1f}")
    print(f"managed server start (fresh PREFECT_HOME): {server_start_s:.2f} s; first runs "
          + ", ".join(f"{g} {s:.2f} s" for g, s in first.items()))
    print(f"{'cached rerun':46s}{'median s':>9s}{'min s':>8s}{'CPU s':>8s}  goal <= {GOAL_S:.0f} s")
    for name, values in rows.items():
        med = statistics.median(values)
        print(f"  {name:44s}{med:>9.2f}{min(values):>8.2f}{statistics.median(cpu[name]):>8.2f}"
              f"  {'met' if med <= GOAL_S else 'NOT met'}")
    print(f"{'one rerun under -X importtime':46s}{'import s':>9s}  heavy packages imported")
    for name, (seconds, heavy) in imports.items():
        print(f"  {name:44s}{seconds:>9.2f}  {', '.join(heavy) or '-'}")
    return {"run": RUN, "repeats": REPEATS, "server_start_s": server_start_s, "first_s": first,
            "median_s": {n: statistics.median(v) for n, v in rows.items()},
            "min_s": {n: min(v) for n, v in rows.items()},
            "median_cpu_s": {n: statistics.median(v) for n, v in cpu.items()},
            "import_s": {n: s for n, (s, _) in imports.items()},
            "heavy_imports": {n: h for n, (_, h) in imports.items()}}


if __name__ == "__main__":
    main()
