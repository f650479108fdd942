"""Run benchmarks and print their figures.

    python -m benchmarks              # every benchmarks/bench_*.py
    python -m benchmarks radar detect # only bench_radar.py and bench_detect.py

Each ``bench_<name>.py`` defines ``main() -> dict`` that prints its figures and returns them.
"""

from __future__ import annotations

import importlib
import json
import platform
import sys
import time
from pathlib import Path


def _machine() -> str:
    import os

    return f"{platform.machine()} {os.cpu_count()} cores, Python {platform.python_version()}"


def main(argv: list[str] | None = None) -> int:
    names = argv if argv is not None else sys.argv[1:]
    here = Path(__file__).parent
    available = sorted(p.stem.removeprefix("bench_") for p in here.glob("bench_*.py"))
    chosen = names or available
    unknown = [n for n in chosen if n not in available]
    if unknown:
        print(f"unknown benchmark(s) {unknown}; available: {available}", file=sys.stderr)
        return 2
    print(f"# sim2radar benchmarks — {time.strftime('%Y-%m-%d')} — {_machine()}")
    results = {}
    for name in chosen:
        print(f"\n## {name}")
        module = importlib.import_module(f"benchmarks.bench_{name}")
        results[name] = module.main()
    print("\n" + json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
