"""Prefect start-up and per-command overhead of ``sim2radar generate``: wall seconds of the same
small run (one world, ground-truth geometry, a small rig) as a user types it, each a new
process, first into an empty store ("first": everything computed) and then again ("cached":
a rerun of a finished dataset, nothing recomputed):

* ``managed, fresh home``    — a new ``PREFECT_HOME``: the first command starts the managed
  local server (database migration included), the cached rerun reuses it;
* ``managed, running server`` — the same ``PREFECT_HOME`` with its server already up (every
  command after the first one);
* ``ephemeral, fresh home``  — ``SIM2RADAR_PREFECT_SERVER=ephemeral``: Prefect's temporary
  API started by every command (the behaviour before issue #16);
* ``--no-prefect``            — the plain loop, no Prefect engine (the floor).

Also the start of a managed server alone (``sim2radar server start`` on an existing home and
on a fresh one) and its idle cost (resident memory, CPU over 10 s). Every server started here
is stopped at the end. Median (and min) over ``SIM2RADAR_BENCH_PREFECT_REPEATS`` rounds (3).

    python -m benchmarks prefect_startup
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sim2radar.cli import server as srv

REPO = Path(__file__).resolve().parents[1]
REPEATS = int(os.environ.get("SIM2RADAR_BENCH_PREFECT_REPEATS", "3"))
RUN = ["--worlds", "1", "--frames", "2", "--width", "160", "--height", "120", "--spp", "4",
       "--geometry", "ground_truth", "--no-png"]
CLI = [sys.executable, "-c", "from sim2radar.cli import main; main()"]


def _env(home: Path, mode: str = "managed") -> dict[str, str]:
    env = {**os.environ, "PREFECT_HOME": str(home), srv.MODE_ENV: mode,
           "PREFECT_SERVER_ANALYTICS_ENABLED": "false"}
    env.pop("PREFECT_API_URL", None)
    return env


def _timed(args: list[str], env: dict[str, str]) -> float:
    """Wall seconds of one CLI command in a new process (it must succeed)."""
    t0 = time.perf_counter()
    res = subprocess.run([*CLI, *args], cwd=REPO, env=env, capture_output=True, text=True)
    wall_s = time.perf_counter() - t0
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({res.returncode}):\n{res.stderr[-3000:]}")
    return wall_s


def _first_and_cached(store: Path, env: dict[str, str], *extra: str) -> tuple[float, float]:
    args = ["generate", *RUN, "--out", str(store), *extra]
    return _timed(args, env), _timed(args, env)


def _idle_cost(pid: int, seconds: float = 10.0) -> tuple[float, float]:
    """(resident memory [MiB], CPU [% of one core]) of an idle server over ``seconds``."""
    def cpu_s() -> float:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    c0 = cpu_s()
    time.sleep(seconds)
    cpu_pct = 100 * (cpu_s() - c0) / seconds
    rss_kib = next(int(line.split()[1]) for line in
                   Path(f"/proc/{pid}/status").read_text().splitlines()
                   if line.startswith("VmRSS:"))
    return rss_kib / 1024, cpu_pct


def main() -> dict:
    rows: dict[str, list[float]] = {}

    def add(name: str, value: float) -> None:
        rows.setdefault(name, []).append(value)

    homes: list[Path] = []
    idle = (float("nan"), float("nan"))
    with tempfile.TemporaryDirectory(prefix="bench-prefect-") as tmp:
        root = Path(tmp)
        try:
            for r in range(REPEATS):
                home = root / f"home{r}"
                homes.append(home)
                first, cached = _first_and_cached(root / f"m{r}", _env(home))
                add("managed, fresh home: first", first)
                add("managed, fresh home: cached", cached)
                first, cached = _first_and_cached(root / f"s{r}", _env(home))
                add("managed, running server: first", first)
                add("managed, running server: cached", cached)
                if r == 0:
                    idle = _idle_cost(srv.read_state(home).pid)
                srv.stop_server(home)
                add("server start, existing home", _timed(["server", "start"], _env(home)))
                srv.stop_server(home)
                fresh = root / f"fresh{r}"
                homes.append(fresh)
                add("server start, fresh home", _timed(["server", "start"], _env(fresh)))
                srv.stop_server(fresh)
                first, cached = _first_and_cached(root / f"e{r}",
                                                  _env(root / f"eph{r}", "ephemeral"))
                add("ephemeral, fresh home: first", first)
                add("ephemeral, fresh home: cached", cached)
                first, cached = _first_and_cached(root / f"n{r}", _env(home), "--no-prefect")
                add("--no-prefect: first", first)
                add("--no-prefect: cached", cached)
        finally:
            for home in homes:
                srv.stop_server(home)
    print(f"generate {' '.join(RUN)}; each a new process; {REPEATS} round(s); "
          f"load average (1 min) at the end {os.getloadavg()[0]:.1f}")
    print(f"{'':36s}{'median s':>10s}{'min s':>8s}")
    for name, values in rows.items():
        print(f"  {name:34s}{statistics.median(values):>10.2f}{min(values):>8.2f}")
    print(f"idle managed server: {idle[0]:.0f} MiB resident, {idle[1]:.1f} % of one core")
    med = {name: statistics.median(v) for name, v in rows.items()}
    floor = med["--no-prefect: cached"]
    print(f"Prefect overhead of a cached rerun over --no-prefect: managed "
          f"{med['managed, running server: cached'] - floor:+.2f} s, ephemeral "
          f"{med['ephemeral, fresh home: cached'] - floor:+.2f} s")
    return {"run": RUN, "repeats": REPEATS, "median_s": med,
            "min_s": {name: min(v) for name, v in rows.items()},
            "idle_server_mib": idle[0], "idle_server_cpu_pct": idle[1]}


if __name__ == "__main__":
    main()
