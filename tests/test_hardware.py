"""Tests for sim2radar/hardware.py (run in subprocesses: the variant choice is process-wide)."""

import subprocess
import sys


def _run(code: str, **env) -> subprocess.CompletedProcess:
    import os

    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, **env}, timeout=120)


def test_variant_is_a_working_llvm_or_cuda_one_and_thread_cap_applies():
    proc = _run("import drjit as dr; from sim2radar.hardware import mitsuba_variant; "
                "v = mitsuba_variant(); print(v, dr.thread_count())",
                SIM2RADAR_DRJIT_THREADS="1")
    assert proc.returncode == 0, proc.stderr
    variant, threads = proc.stdout.split()
    assert variant in ("cuda_ad_rgb", "llvm_ad_rgb")  # setup installs libllvm19
    assert threads == "1"


def test_bad_overrides_name_the_variable():
    proc = _run("from sim2radar.hardware import mitsuba_variant; mitsuba_variant()",
                SIM2RADAR_MITSUBA_VARIANT="nope_rgb")
    assert proc.returncode != 0 and "SIM2RADAR_MITSUBA_VARIANT='nope_rgb'" in proc.stderr
    proc = _run("from sim2radar.hardware import mitsuba_variant; mitsuba_variant()",
                SIM2RADAR_DRJIT_THREADS="zero")
    assert proc.returncode != 0 and "SIM2RADAR_DRJIT_THREADS" in proc.stderr
