"""Worlds on a thread pool (``generate --workers N``): the renderer and the ray tracer share
one Dr.Jit state per process, so their Dr.Jit work runs one thread at a time
(sim2radar.hardware.DRJIT_LOCK). Without it a reference run with two workers failed a frame with
"Variable ... remains dirty despite an attempt to evaluate it" (a scatter evaluated while
another thread recorded a symbolic loop). That race is rare (one frame of a 618-frame run) and
this test does not reproduce it reliably without the lock; it checks that threads rendering and
tracing at once finish and give the frames a thread alone gives."""

from __future__ import annotations

import threading

import numpy as np

from sim2radar.radar import RadarScene, load_radar_config
from sim2radar.worlds import render_frame, trajectory
from tests.worlds._helpers import SMALL_RIG


def test_threads_rendering_and_tracing_at_once_give_the_serial_results(world3):
    poses = trajectory(world3, 2, seed=0)
    radar = load_radar_config("ti-mmwcas")
    scene = RadarScene(list(world3.meshes))
    alone = scene.simulate(radar, render_frame(world3, poses[0], SMALL_RIG).radar_to_world,
                           seed=1)
    gate, errors, traced = threading.Barrier(3), [], []

    def trace():
        gate.wait()
        for _ in range(3):
            frame = render_frame(world3, poses[0], SMALL_RIG, rgb=False)
            traced.append(scene.simulate(radar, frame.radar_to_world, seed=1))

    def render():
        gate.wait()
        for p in poses * 2:
            render_frame(world3, p, SMALL_RIG)

    def guarded(fn):
        def run():
            try:
                fn()
            except Exception as exc:  # noqa: BLE001 - the test reports any thread's failure
                errors.append(exc)
        return run

    threads = [threading.Thread(target=guarded(f)) for f in (trace, trace, render)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    assert len(traced) == 6
    for frame in traced:  # the same frame as traced alone: nothing leaked between threads
        np.testing.assert_array_equal(frame.points, alone.points)
