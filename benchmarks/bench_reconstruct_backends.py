"""Production reconstruction backends (helper E1): LiDAR depth completion accuracy and speed,
MoGe post-processing time, VLM client throughput / cache against a loopback server.

    python -m benchmarks reconstruct_backends
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from sim2radar.reconstruct.depth_lidar import LidarDepth
from sim2radar.reconstruct.depth_moge import MogeDepth
from sim2radar.reconstruct.materials_vlm import VlmMaterials
from sim2radar.reconstruct.synthetic import corridor_frame
from sim2radar.reconstruct.types import DepthResult, FrameInput, Segments


def _timed(fn, n=3):
    fn()
    t = time.perf_counter()
    for _ in range(n):
        out = fn()
    return out, (time.perf_counter() - t) / n


def _depth_scores(pred, gt):
    v = (pred > 0) & (gt > 0)
    ratio = np.maximum(pred[v] / gt[v], gt[v] / pred[v])
    return float(np.mean(np.abs(pred[v] - gt[v]) / gt[v])), float(np.mean(ratio < 1.25)), \
        float(v.mean())


def _frames():
    frames = [("analytic corridor 96x72", corridor_frame(seed=s)) for s in range(4)]
    try:
        from sim2radar.worlds import RigConfig, generate_world, render_frame, trajectory

        for seed in (0, 1):
            world = generate_world(seed=seed)
            frames.append(("procedural world 640x480",
                           render_frame(world, trajectory(world, n_frames=1, seed=0)[0],
                                        RigConfig())))
    except Exception as exc:  # worlds optional here
        print(f"(procedural worlds skipped: {exc})")
    return frames


def main() -> dict:
    out: dict = {}
    groups: dict = {}
    for name, f in _frames():
        fr = FrameInput(f.rgb, f.intrinsics, f.lidar_points)
        for mode, opts in (("guided", {}), ("colour-blind", {"sigma_color": 1e4})):
            res, dt = _timed(lambda fr=fr, opts=opts: LidarDepth(**opts).estimate(fr), n=1)
            groups.setdefault((name, mode), []).append((*_depth_scores(res.depth_m, f.depth_m),
                                                        dt))
    for (name, mode), rows in groups.items():
        a = np.mean(rows, axis=0)
        key = f"lidar {mode} — {name}"
        out[key] = {"absrel": round(a[0], 4), "delta1": round(a[1], 3),
                    "coverage": round(a[2], 3), "ms": round(a[3] * 1e3), "frames": len(rows)}
        print(f"{key:45s} AbsRel {a[0]:.4f}  δ<1.25 {a[1]:.3f}  coverage {a[2]:.3f}  "
              f"{a[3] * 1e3:.0f} ms/frame  ({len(rows)} frames)")

    from sim2radar.camera import CameraIntrinsics
    from tests.reconstruct._models import export_moge_like  # tiny MoGe-2-signature model

    with tempfile.TemporaryDirectory() as d:
        k = CameraIntrinsics.from_fov(640, 480, 70)
        p = export_moge_like(Path(d) / "m.onnx", plane=(0.03, 0.12, 0.25), ref_intrinsics=k,
                             scale=2.0, shift=0.7)
        fr = FrameInput(np.zeros((480, 640, 3), np.uint8), k)
        for label, opts in (("known K", {}), ("focal recovered", {"recover_focal": True})):
            _, dt = _timed(lambda opts=opts: MogeDepth(model_path=str(p), **opts).estimate(fr))
            out[f"moge post-processing 640x480 {label} ms"] = round(dt * 1e3)
            print(f"moge post-processing 640x480 ({label}, tiny graph): {dt * 1e3:.0f} ms")

    from tests.reconstruct._vlm_server import VlmTestServer

    h, w, n = 240, 320, 32
    seg = np.minimum(np.arange(h * w).reshape(h, w) // (h * w // n), n - 1).astype(np.int32)
    rgb = np.random.default_rng(0).integers(0, 255, (h, w, 3), dtype=np.uint8)
    fr = FrameInput(rgb, CameraIntrinsics.from_fov(w, h, 60))
    segs = Segments(seg, ("wall",) * n, np.ones(n, np.float32))
    depth = DepthResult(np.ones((h, w), np.float32))
    for conc in (1, 4):
        with VlmTestServer("json", delay_s=0.05) as srv:
            t = time.perf_counter()
            VlmMaterials(base_url=srv.base_url, max_concurrency=conc).label(fr, depth, segs)
            dt = time.perf_counter() - t
        out[f"vlm segments/s (50 ms server, concurrency {conc})"] = round(n / dt, 1)
        print(f"vlm {n} segments, 50 ms server latency, concurrency {conc}: {n / dt:.1f} seg/s")
    with tempfile.TemporaryDirectory() as d, VlmTestServer("json") as srv:
        VlmMaterials(base_url=srv.base_url, cache_path=f"{d}/c.sqlite").label(fr, depth, segs)
        t = time.perf_counter()
        VlmMaterials(base_url=srv.base_url, cache_path=f"{d}/c.sqlite").label(fr, depth, segs)
        dt = time.perf_counter() - t
    out["vlm 32 cached segments ms"] = round(dt * 1e3)
    print(f"vlm {n} segments, all cached: {dt * 1e3:.0f} ms")
    return out


if __name__ == "__main__":
    main()
