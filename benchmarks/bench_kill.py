"""A factory run stopped by a scheduler: ``sim2radar generate`` sent SIGTERM mid-world, N times.

Each round starts ``generate`` (one world of 8 frames, 80x60 px, ground-truth geometry, OpenPCDet
export) on the managed Prefect server of one ``PREFECT_HOME``, waits until the world is rendered
(its ``world_specs`` artifact appears), waits a random 0-1 s more, sends SIGTERM to the run's
process, as a scheduler or ``kill PID`` does, and times how long the process takes to go. It
reports the exit codes (-15 expected; -11 is a segmentation fault), the seconds from SIGTERM to
exit and the frames the run had published. Prefect's own thread pool made a SIGTERM'd run
finish its world first; :class:`sim2radar.flows.runners.ThreadRunner` does not wait.

    SIM2RADAR_BENCH_KILL_ROUNDS=100 python -m benchmarks kill      # default 20 rounds
"""

from __future__ import annotations

import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sim2radar.cli import server as srv

REPO = Path(__file__).resolve().parents[1]
ROUNDS = int(os.environ.get("SIM2RADAR_BENCH_KILL_ROUNDS", "20"))
RUN = ["generate", "--worlds", "1", "--frames", "8", "--width", "80", "--height", "60",
       "--spp", "2", "--geometry", "ground_truth", "--no-png"]
CLI = [sys.executable, "-c", "from sim2radar.cli import main; main()"]


def main() -> dict:
    rng = random.Random(0)
    with tempfile.TemporaryDirectory(prefix="bench-kill-") as tmp:
        home = Path(tmp) / "prefect"
        env = {**os.environ, "PREFECT_HOME": str(home), srv.MODE_ENV: "managed",
               "PREFECT_SERVER_ANALYTICS_ENABLED": "false"}
        env.pop("PREFECT_API_URL", None)
        srv.ensure_server(home)
        codes, exit_s, frames = [], [], []
        try:
            for i in range(ROUNDS):
                store = Path(tmp) / f"store{i}"
                proc = subprocess.Popen([*CLI, *RUN, "--out", str(store), "--export-openpcdet",
                                         str(Path(tmp) / f"export{i}")], cwd=REPO, env=env,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                deadline = time.monotonic() + 300
                while not list(store.glob("world_specs/*.parquet")) and proc.poll() is None \
                        and time.monotonic() < deadline:
                    time.sleep(0.02)
                time.sleep(rng.uniform(0.0, 1.0))
                t0 = time.monotonic()
                proc.send_signal(signal.SIGTERM)
                proc.wait(timeout=300)
                exit_s.append(time.monotonic() - t0)
                codes.append(proc.returncode)
                frames.append(len(list(store.glob("dataset_frames/*.parquet"))))
        finally:
            srv.stop_server(home)
    out = {
        "rounds": ROUNDS,
        "exit_codes": {str(c): codes.count(c) for c in sorted(set(codes))},
        "segfaults": codes.count(-signal.SIGSEGV),
        "sigterm_to_exit_s_median": round(statistics.median(exit_s), 3),
        "sigterm_to_exit_s_max": round(max(exit_s), 3),
        "frames_published_of_8_median": statistics.median(frames),
        "load_average_1min": round(os.getloadavg()[0], 2),
    }
    for k, v in out.items():
        print(f"{k:32s} {v}")
    return out
