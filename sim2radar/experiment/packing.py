"""Several training runs on one GPU: how many, by measurement.

A small detector leaves most of a GPU idle (on one H100 the paper model's step used 1 GiB of
80 and waited on the host for two thirds of its 41 ms): N runs in N processes sharing the
device finish a grid faster than one at a time — up to the point where they only slow each
other down. :func:`aggregate_throughput` starts N training processes together on the device
and measures their optimiser steps per second in aggregate; :func:`choose_runs` takes the
smallest N within reach of the best.

    per_n = aggregate_throughput(cfg, "cuda", counts=(1, 2, 4, 8))   # {1: 24.1, 2: 41.0, ...}
    decision = choose_runs(per_n)                                     # PackingDecision(runs=8, ...)

The rule (fixed before a measurement): a larger N is taken only when it gives at least
:data:`MIN_GAIN` (10 %) more aggregate steps per second than the best smaller N — more
processes cost memory and make each run slower, so a marginal gain is not worth them.

``auto`` (:func:`probe_runs`) measures :data:`PROBE_COUNTS` and keeps doubling N while the
last doubling still gained :data:`MIN_GAIN`, up to :data:`MAX_PROBE_RUNS`: on one H100 the
paper model went 61.8 / 86.1 / 126.4 / 205.1 steps/s for 1 / 2 / 4 / 8 runs, still rising, so
a fixed (1, 2, 4, 8) stopped where the curve had not. A count whose probe fails (the device
out of memory) ends the climb; the counts measured before it decide.
"""

from __future__ import annotations

import dataclasses
import json
import os
import statistics
import subprocess
import sys
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["GPU_RESOURCE", "MAX_PROBE_RUNS", "MIN_GAIN", "PROBE_COUNTS", "PackingDecision",
           "aggregate_throughput", "choose_runs", "decide_runs", "probe_runs"]

#: the Dask worker resource a packed sweep's training task claims one unit of: start a GPU
#: worker with ``dask worker ADDRESS --nthreads N --resources GPU_RUNS=N`` to run N at once
GPU_RESOURCE = "GPU_RUNS"

#: a larger number of runs per device must beat the best smaller one by this fraction
MIN_GAIN = 0.10
#: runs per device ``auto`` always measures
PROBE_COUNTS = (1, 2, 4, 8)
#: ``auto`` doubles past :data:`PROBE_COUNTS` up to this many runs per device
MAX_PROBE_RUNS = 32

#: one training process of the probe: prints its median seconds per step as JSON
_WORKER = r"""
import json, sys, torch
from sim2radar.detect.config import DetectConfig
from sim2radar.detect.precision import probe_step_seconds
cfg = DetectConfig.model_validate(json.loads(sys.argv[1]))
device, steps = sys.argv[2], int(sys.argv[3])
if cfg.runtime.num_threads:
    torch.set_num_threads(cfg.runtime.num_threads)
dtype = None
if cfg.runtime.amp:
    from sim2radar.hardware import autocast_dtype
    dtype = autocast_dtype(device, True)
print(json.dumps({"s": probe_step_seconds(cfg, device, dtype, steps=steps)}))
"""


@dataclasses.dataclass(frozen=True)
class PackingDecision:
    """How many training runs share one device.

    Attributes
    ----------
    runs : int — concurrent runs per device.
    steps_per_s : dict — runs -> aggregate optimiser steps per second measured (empty when
        the number was given).
    source : str — ``probe`` (measured, :func:`choose_runs`) or ``given``.
    reason : str — one sentence.
    """

    runs: int
    steps_per_s: dict[int, float] = dataclasses.field(default_factory=dict)
    source: str = "given"
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"runs": self.runs, "steps_per_s": {str(k): v for k, v in
                                                   self.steps_per_s.items()},
                "source": self.source, "reason": self.reason}

    def seconds_per_step(self) -> float | None:
        """One run's seconds per step while ``runs`` share the device (None: not measured)."""
        agg = self.steps_per_s.get(self.runs)
        return None if not agg else self.runs / agg


def aggregate_throughput(cfg, device: str, counts: Sequence[int] = PROBE_COUNTS, *,
                         steps: int = 20) -> dict[int, float]:
    """Aggregate optimiser steps per second of N training processes started together on
    ``device``, for each N in ``counts``: each process trains ``cfg``'s model (its precision
    and threads as resolved) for ``steps`` timed steps
    (:func:`sim2radar.detect.precision.probe_step_seconds`); aggregate = N / median step.

    Raises
    ------
    RuntimeError — a probe process failed (its stderr's last lines in the message).
    """
    doc = json.dumps(cfg.model_dump(mode="json"))
    env = dict(os.environ)
    if cfg.runtime.num_threads:
        env["OMP_NUM_THREADS"] = str(cfg.runtime.num_threads)
    out = {}
    for n in counts:
        procs = [subprocess.Popen([sys.executable, "-c", _WORKER, doc, str(device), str(steps)],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                  env=env) for _ in range(int(n))]
        per = []
        for p in procs:
            stdout, stderr = p.communicate()
            if p.returncode != 0:
                tail = "\n".join(stderr.strip().splitlines()[-5:])
                raise RuntimeError(f"runs-per-device probe ({n} processes on {device}) failed "
                                   f"with exit status {p.returncode}:\n{tail}")
            per.append(json.loads(stdout.strip().splitlines()[-1])["s"])
        out[int(n)] = round(int(n) / statistics.median(per), 3)
    return out


def probe_runs(cfg, device: str, *, steps: int = 20) -> tuple[dict[int, float], str]:
    """``auto``'s measurements (:func:`aggregate_throughput`): aggregate steps per second for
    :data:`PROBE_COUNTS`, then for twice the largest count while the last doubling gained at
    least :data:`MIN_GAIN`, up to :data:`MAX_PROBE_RUNS`. Returns ``(steps_per_s, note)``;
    ``note`` says why the climb stopped at a failed count ("" otherwise)."""
    per_n = dict(aggregate_throughput(cfg, device, PROBE_COUNTS, steps=steps))
    n = max(per_n)
    while 2 * n <= MAX_PROBE_RUNS and per_n[n] >= (1.0 + MIN_GAIN) * per_n.get(n // 2, 0.0):
        try:
            per_n.update(aggregate_throughput(cfg, device, (2 * n,), steps=steps))
        except RuntimeError as exc:
            return per_n, f"{2 * n} runs failed ({str(exc).splitlines()[-1][:200]})"
        n *= 2
    return per_n, ""


def choose_runs(steps_per_s: Mapping[int, float], min_gain: float = MIN_GAIN
                ) -> PackingDecision:
    """The runs per device to use: walking up the measured counts, a larger N replaces the
    best so far only when its aggregate throughput is at least ``min_gain`` higher."""
    if not steps_per_s:
        raise ValueError("no throughput measured")
    ordered = sorted((int(n), float(v)) for n, v in steps_per_s.items())
    best_n, best = ordered[0]
    for n, v in ordered[1:]:
        if v >= (1.0 + min_gain) * best:
            best_n, best = n, v
    shown = ", ".join(f"{n}: {v:.1f}" for n, v in ordered)
    return PackingDecision(best_n, dict(ordered), "probe",
                           f"aggregate steps/s by runs per device {{{shown}}}: {best_n} "
                           f"(a larger count must add >= {min_gain:.0%})")


def decide_runs(cfg, device: str, runs_per_gpu: int | str, *, measure: bool = False,
                steps: int = 20) -> PackingDecision:
    """The runs per device for ``--runs-per-gpu``: ``"auto"`` measured (:func:`probe_runs`)
    and chosen (:func:`choose_runs`); a count as given, its aggregate throughput measured too
    when ``measure`` (a plan needs the figure, a sweep does not)."""
    if runs_per_gpu == "auto":
        per_n, note = probe_runs(cfg, device, steps=steps)
        decision = choose_runs(per_n)
        if note:
            decision = dataclasses.replace(decision, reason=f"{decision.reason}; {note}")
        return decision
    n = int(runs_per_gpu)
    if measure:
        return dataclasses.replace(choose_runs(aggregate_throughput(cfg, device, (n,),
                                                                    steps=steps)),
                                   source="given", reason="given (--runs-per-gpu), measured")
    return PackingDecision(n, reason="given (--runs-per-gpu)")
