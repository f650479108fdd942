"""Tests for sim2radar/hardware.py (run in subprocesses: the variant choice is process-wide)."""

import subprocess
import sys
import threading

import pytest


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


def test_threads_choosing_the_variant_at_once_all_get_it():
    """Worlds on a thread pool reach mitsuba_variant() together; each must get the working
    variant (a --workers 2 run once failed a world on a half-initialised Mitsuba)."""
    proc = _run("import threading\n"
                "from sim2radar.hardware import mitsuba_variant\n"
                "gate, out = threading.Barrier(6), []\n"
                "def go():\n"
                "    gate.wait()\n"
                "    try: out.append(mitsuba_variant())\n"
                "    except Exception as e: out.append(repr(e))\n"
                "ts = [threading.Thread(target=go) for _ in range(6)]\n"
                "[t.start() for t in ts]; [t.join() for t in ts]\n"
                "print(' '.join(out), mitsuba_variant.cache_info().currsize)\n")
    assert proc.returncode == 0, proc.stderr
    *variants, cached = proc.stdout.split()
    assert len(variants) == 6 and set(variants) <= {"cuda_ad_rgb", "llvm_ad_rgb"}
    assert len(set(variants)) == 1 and cached == "1"


def test_bad_overrides_name_the_variable():
    proc = _run("from sim2radar.hardware import mitsuba_variant; mitsuba_variant()",
                SIM2RADAR_MITSUBA_VARIANT="nope_rgb")
    assert proc.returncode != 0 and "SIM2RADAR_MITSUBA_VARIANT='nope_rgb'" in proc.stderr
    proc = _run("from sim2radar.hardware import mitsuba_variant; mitsuba_variant()",
                SIM2RADAR_DRJIT_THREADS="zero")
    assert proc.returncode != 0 and "SIM2RADAR_DRJIT_THREADS" in proc.stderr


# 161 float32 ending exactly where the readable memory ends (the next page has no access): how
# NumPy's exact-size buffers sit at the top of a heap now and then
_AT_A_GUARD_PAGE = """
import ctypes, mmap, numpy as np, drjit as dr, mitsuba as mi
from sim2radar.hardware import mitsuba_variant, to_drjit
mitsuba_variant()
page = mmap.PAGESIZE
m = mmap.mmap(-1, 2 * page, prot=mmap.PROT_READ | mmap.PROT_WRITE)
base = ctypes.addressof(ctypes.c_char.from_buffer(m))
assert ctypes.CDLL(None).mprotect(ctypes.c_void_p(base + page), page, 0) == 0
values = np.frombuffer(m, dtype=np.float32, count=page // 4)[-161:]
values[:] = np.arange(161)
x = {make}(mi.Float, values) if "{make}" == "to_drjit" else mi.Float(values)
print(float(dr.sum(x * 2.0 + 1.0)[0]))
"""


def test_numpy_data_enters_drjit_with_slack_after_its_end():
    """Dr.Jit's LLVM backend keeps a contiguous NumPy buffer instead of copying it, and its
    kernels read whole vector packets past the end: a buffer that ends at unreadable memory
    crashes the kernel (the factory's rare SIGSEGV in the visibility query). ``to_drjit`` copies
    into a buffer with slack: the same data then sums correctly."""
    safe = _run(_AT_A_GUARD_PAGE.replace("{make}", "to_drjit"))
    assert safe.returncode == 0, safe.stderr[-2000:]
    assert float(safe.stdout.split()[-1]) == 2 * sum(range(161)) + 161
    raw = _run(_AT_A_GUARD_PAGE.replace("{make}", "raw"))
    # the hazard itself (in Dr.Jit 1.5 / Mitsuba 3.9 on a CPU with 16-lane packets; a release
    # that copies or pads would print the sum instead, and to_drjit would be belt and braces)
    assert raw.returncode in (-11, 0), raw.stderr[-2000:]


def test_to_drjit_copies_and_keeps_components_apart():
    proc = _run("import numpy as np, mitsuba as mi; "
                "from sim2radar.hardware import mitsuba_variant, to_drjit; mitsuba_variant(); "
                "a = np.arange(6.0).reshape(3, 2); p = to_drjit(mi.Point3f, a, np.float32); "
                "a[:] = -1; print(p.x, p.y, p.z, to_drjit(mi.UInt32, [4, 5], np.uint32)); "
                "to_drjit(mi.Point3f, np.zeros((2, 4)))")
    assert "[0, 1] [2, 3] [4, 5] [4, 5]" in proc.stdout, proc.stdout + proc.stderr
    assert proc.returncode != 0 and "Point3f needs (3, N) values" in proc.stderr


def test_mixed_precision_choice(monkeypatch):
    """amp: false -> float32; true -> bfloat16 on a CPU; auto -> bfloat16 only on a CPU with
    native bfloat16 (else float32, where emulated bfloat16 would be slower)."""
    import torch

    from sim2radar import hardware

    assert hardware.autocast_dtype("cpu", False) is None
    assert hardware.autocast_dtype("cpu", True) is torch.bfloat16
    for native in (True, False):
        monkeypatch.setattr(hardware, "cpu_has_native_bf16", lambda native=native: native)
        assert hardware.autocast_dtype("cpu", "auto") is (torch.bfloat16 if native else None)
    with pytest.raises(ValueError, match="amp must be"):
        hardware.autocast_dtype("cpu", "fast")


def test_native_bf16_is_read_from_the_cpu_flags():
    from pathlib import Path

    from sim2radar import hardware

    info = Path("/proc/cpuinfo")
    if not info.is_file():
        assert hardware.cpu_has_native_bf16() is False
        return
    flags = next((line for line in info.read_text().splitlines() if line.startswith("flags")),
                 "")
    assert hardware.cpu_has_native_bf16() == any(f in flags.split()
                                                 for f in hardware.CPU_BF16_FLAGS)


# -- Mitsuba objects die under DRJIT_LOCK (tests/worlds/test_threads.py has the race itself) --

class _Sentinel:
    """Stands in for a Mitsuba object: records the thread it died in."""

    def __init__(self, died_in: list):
        self.died_in = died_in

    def __del__(self):
        self.died_in.append(threading.get_ident())


def _holding_the_lock(fn):
    """Run ``fn`` in a thread that holds DRJIT_LOCK (through drjit_serial) until told to stop;
    returns (stop, thread, ident)."""
    from sim2radar.hardware import drjit_serial

    holding, stop, ident = threading.Event(), threading.Event(), []

    @drjit_serial
    def hold():
        ident.append(threading.get_ident())
        holding.set()
        stop.wait(30)

    thread = threading.Thread(target=hold)
    thread.start()
    assert holding.wait(30)
    fn()
    return stop, thread, ident[0]


def test_an_object_released_while_another_thread_holds_the_lock_dies_in_that_thread():
    from sim2radar.hardware import release_under_lock

    died_in: list = []
    release_under_lock(_Sentinel(died_in))  # lock free: destroyed at once, here
    assert died_in == [threading.get_ident()]

    died_in.clear()
    stop, thread, holder = _holding_the_lock(lambda: release_under_lock(_Sentinel(died_in)))
    assert died_in == []  # kept while the other thread is inside Dr.Jit
    stop.set()
    thread.join(30)
    assert died_in == [holder]  # destroyed by the holder, on its way out, under the lock


def test_an_owner_dropped_outside_the_lock_hands_its_attributes_to_the_holder():
    from sim2radar.hardware import ReleasedUnderLock

    class Owner(ReleasedUnderLock):
        def __init__(self, died_in):
            self.scene = _Sentinel(died_in)

    died_in: list = []
    owner = [Owner(died_in)]
    stop, thread, holder = _holding_the_lock(owner.clear)
    assert died_in == []
    stop.set()
    thread.join(30)
    assert died_in == [holder]


def test_an_exception_leaves_drjit_serial_with_its_frames_locals_destroyed():
    from sim2radar.hardware import drjit_serial

    died_in: list = []

    @drjit_serial
    def fail():
        scene = _Sentinel(died_in)  # noqa: F841 - a Dr.Jit value held by the failing frame
        raise ValueError("bad input")

    with pytest.raises(ValueError, match="bad input") as info:
        fail()
    assert died_in == [threading.get_ident()]  # not kept alive by the traceback
    assert "bad input" in str(info.value)


def test_a_world_dropped_while_another_thread_is_in_drjit_leaves_its_scene_to_that_thread():
    """The two owners of Mitsuba scenes, the renderer's cache and the radar's RadarScene."""
    import numpy as np

    from sim2radar import hardware
    from sim2radar.radar import RadarScene
    from sim2radar.worlds import cast_rays, generate_world
    from sim2radar.worlds.render import _SCENES

    world = [generate_world(3)]
    cast_rays(world[0], np.zeros(3), np.array([[1.0, 0.0, 0.0]]))  # builds and caches its scene
    assert len(_SCENES._cache) >= 1
    before = len(_SCENES._cache)
    stop, thread, _ = _holding_the_lock(world.clear)
    assert len(_SCENES._cache) == before - 1  # out of the cache ...
    assert len(hardware._RELEASED) == 1       # ... and its Mitsuba scene waits for the holder
    stop.set()
    thread.join(30)
    assert hardware._RELEASED == []

    radar_scene = [RadarScene(list(generate_world(3).meshes))]
    stop, thread, _ = _holding_the_lock(radar_scene.clear)
    assert len(hardware._RELEASED) == 1
    stop.set()
    thread.join(30)
    assert hardware._RELEASED == []
