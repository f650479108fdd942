"""Run claims: one process trains a run; a dead holder's claim is taken over; waiters see the
result instead of training again."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from sim2radar.experiment.claims import ClaimTimeout, claim_run, read_events, wait_and_claim

REPO = Path(__file__).resolve().parents[2]


def test_a_held_claim_excludes_others_until_released(tmp_path):
    first = claim_run(tmp_path, "k1")
    assert first is not None
    assert claim_run(tmp_path, "k1") is None                  # held by a live pid (ours)
    assert claim_run(tmp_path, "k2") is not None              # other runs are free
    first.release()
    assert not (tmp_path / "k1.json").exists()
    again = claim_run(tmp_path, "k1")
    assert again is not None
    again.release()
    events = [(e["event"], e["key"]) for e in read_events(tmp_path)]
    assert events[:3] == [("claimed", "k1"), ("claimed", "k2"), ("released", "k1")]


def test_the_heartbeat_keeps_the_claim_fresh(tmp_path):
    claim = claim_run(tmp_path, "k", heartbeat_s=0.05)
    path = tmp_path / "k.json"
    os.utime(path, (time.time() - 1000, time.time() - 1000))
    time.sleep(0.3)
    assert time.time() - path.stat().st_mtime < 5
    claim.release()


def test_a_killed_holders_claim_is_taken_over(tmp_path):
    """A process that claimed and was SIGKILLed leaves its file; its pid is gone, so the claim
    is stale at once and the next process takes it over (logged with the reason)."""
    code = ("import sys, time; from sim2radar.experiment.claims import claim_run; "
            f"c = claim_run({str(tmp_path)!r}, 'k'); print('held', flush=True); time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "held"
        assert claim_run(tmp_path, "k") is None               # alive: not ours to take
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    holder = json.loads((tmp_path / "k.json").read_text())
    assert holder["pid"] == proc.pid
    claim = claim_run(tmp_path, "k")
    assert claim is not None
    takeover = [e for e in read_events(tmp_path) if e["event"] == "takeover"]
    assert len(takeover) == 1 and f"pid {proc.pid}" in takeover[0]["reason"]
    claim.release()


def test_another_hosts_claim_is_stale_only_without_heartbeat(tmp_path):
    path = tmp_path / "k.json"
    path.write_text(json.dumps({"host": "elsewhere.example", "pid": 1, "token": "x"}))
    assert claim_run(tmp_path, "k", stale_after_s=60) is None          # fresh heartbeat
    os.utime(path, (time.time() - 120, time.time() - 120))
    claim = claim_run(tmp_path, "k", stale_after_s=60)
    assert claim is not None
    assert "no heartbeat from elsewhere.example" in read_events(tmp_path)[0]["reason"]
    claim.release()


def test_racing_workers_train_a_run_once(tmp_path):
    """Eight threads want the same run: one trains it, the others wait and find it done."""
    finished = threading.Event()
    trained, skipped = [], []
    lock = threading.Lock()

    def worker():
        claim = wait_and_claim(tmp_path, "run", finished.is_set, poll_s=0.01)
        if claim is None:
            with lock:
                skipped.append(1)
            return
        with claim:
            time.sleep(0.2)                                   # "training"
            with lock:
                trained.append(1)
            finished.set()

    threads = [threading.Thread(target=worker) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert len(trained) == 1 and len(skipped) == 7


def test_waiting_for_a_live_holder_can_time_out(tmp_path):
    held = claim_run(tmp_path, "k")
    seen = []
    with pytest.raises(ClaimTimeout, match="still claimed"):
        wait_and_claim(tmp_path, "k", lambda: False, poll_s=0.01, timeout_s=0.1,
                       on_wait=seen.append)
    assert seen and seen[0]["pid"] == os.getpid()
    held.release()


def test_a_sweep_waiting_on_another_hosts_claim_says_so(tmp_path, caplog):
    """Issue #33, probe 7: a fresh claim from another host held a sweep up to 2 minutes with no
    message; now one warning names the holder, the claim file and why it waits."""
    import logging
    from types import SimpleNamespace

    from sim2radar.tasks.experiment import _claim

    (tmp_path / "claims").mkdir()
    (tmp_path / "claims" / "k.json").write_text(
        json.dumps({"host": "elsewhere.example", "pid": 4242, "token": "x"}))
    finished = threading.Event()
    threading.Timer(0.5, finished.set).start()
    logger = logging.getLogger("sim2radar.tasks.experiment")
    logger.addHandler(caplog.handler)
    try:
        assert _claim(SimpleNamespace(sweep_dir=str(tmp_path)), "k", finished.is_set,
                      tmp_path / "runs" / "k", "run baseline-f0.05-t0") is None
    finally:
        logger.removeHandler(caplog.handler)
    said = list({id(r): r.getMessage() for r in caplog.records
                 if "is claimed by" in r.getMessage()}.values())
    assert len(said) == 1       # (caplog may see a record twice: through root and our handler)
    assert "pid 4242 on elsewhere.example" in said[0] and "k.json" in said[0]
    assert "stale" in said[0] and "another host" in said[0]
