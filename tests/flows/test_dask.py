"""Both factory flows on a real Dask cluster (``distributed.LocalCluster``, 2 worker processes,
127.0.0.1 only) give the same artifacts as the thread runner, record failures, and skip on a
second run; the runner helper picks the right runner and fails clearly.

Tiny inputs (plate scenes, 80 x 60 px worlds, 2 spp, a 0.5 deg radar ray grid) keep the file
well under a minute on 2 cores. Skipped when prefect-dask is not installed.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from prefect.flows import load_flow_from_entrypoint

from tests.flows._scenes import RADAR_POSITION, RADAR_YAW_DEG, write_scene

REPO = Path(__file__).resolve().parents[2]
WORLD = {"corridor_length_m": [10, 12], "layout_probs": {"straight": 1.0}}
RIG = {"width": 80, "height": 60, "spp": 2, "lidar_azimuth_step_deg": 1.0}
BROKEN_SEED = -1  # world generation refuses negative seeds


def _mitsuba_state() -> dict:
    """Run inside a Dask worker: which process it is and whether it picked a Mitsuba variant."""
    from sim2radar.hardware import mitsuba_variant

    return {"pid": os.getpid(), "mitsuba": "mitsuba" in sys.modules,
            "variant_cached": mitsuba_variant.cache_info().currsize}


@pytest.fixture(scope="module")
def cluster():
    """A 2-process LocalCluster on loopback (no dashboard), closed after the module."""
    pytest.importorskip("prefect_dask")
    distributed = pytest.importorskip("distributed")
    from sim2radar.flows.runners import local_cluster_kwargs

    with distributed.LocalCluster(**local_cluster_kwargs(2)) as lc:
        assert lc.scheduler_address.startswith("tcp://127.0.0.1:")
        yield lc


def _client_run(cluster, fn):
    import distributed

    with distributed.Client(cluster.scheduler_address, set_as_default=False) as client:
        return client.run(fn)


def _plate(folder, name, range_m):
    centre = (RADAR_POSITION[0], RADAR_POSITION[1] + range_m, RADAR_POSITION[2])
    return write_scene(folder / name, name, [(name, "metal", centre, (1.0, 0.02, 1.0))],
                       poses=[{"position": list(RADAR_POSITION), "yaw_deg": RADAR_YAW_DEG}])


def _same_points(a, b, tol_m=1e-3, tol_db=0.05, min_matched=0.98):
    """Point clouds equal up to float32 summation order (Dr.Jit's multi-threaded LLVM backend
    does not fix it, even within one process): nearly every point of each cloud has a twin in
    the other within ``tol_m`` [m] and ``tol_db`` [dB]."""
    from scipy.spatial import cKDTree

    if abs(len(a) - len(b)) > max(1, (1 - min_matched) * max(len(a), len(b))):
        return False
    for p, q in ((a, b), (b, a)):
        dist, idx = cKDTree(q[:, :3]).query(p[:, :3])
        ok = (dist <= tol_m) & (np.abs(p[:, 3] - q[idx, 3]) <= tol_db)
        if ok.mean() < min_matched:
            return False
    return True


def _parquet_mtimes(root):
    return {p: os.path.getmtime(p) for p in root.rglob("*.parquet") if "manifests" not in p.parts}


def test_task_runner_choice_and_errors(monkeypatch):
    from prefect.task_runners import ThreadPoolTaskRunner
    from prefect_dask import DaskTaskRunner

    from sim2radar.flows.runners import task_runner

    threads = task_runner(3)
    assert isinstance(threads, ThreadPoolTaskRunner) and threads._max_workers == 3
    local = task_runner(2, "local")
    assert isinstance(local, DaskTaskRunner) and local.address is None
    assert local.cluster_kwargs["n_workers"] == 2 and local.cluster_kwargs["processes"] is True
    assert local.cluster_kwargs["threads_per_worker"] == 1
    assert local.cluster_kwargs["host"] == "127.0.0.1"
    remote = task_runner(1, "tcp://127.0.0.1:8786", check=False)
    assert remote.address == "tcp://127.0.0.1:8786" and remote.duplicate() == remote
    with pytest.raises(ValueError, match="workers"):
        task_runner(0)
    with pytest.raises(ValueError, match="tcp://127.0.0.1:8786"):
        task_runner(1, "my-laptop")
    monkeypatch.setitem(sys.modules, "prefect_dask", None)  # as if not installed
    with pytest.raises(ImportError, match=r"sim2radar\[dask\]"):
        task_runner(2, "local")
    assert isinstance(task_runner(1, None), ThreadPoolTaskRunner)  # threads need nothing


def test_workers_are_probed_before_use(cluster):
    from sim2radar.flows.runners import _worker_problems, check_dask_workers, task_runner

    probes = check_dask_workers(cluster.scheduler_address)
    assert len(probes) == 2
    for found in probes.values():  # the installed package, from the checkout's folders
        assert found["sim2radar.storage"] == str(REPO / "storage" / "__init__.py")
        assert found["sim2radar.tasks"] == str(REPO / "tasks" / "__init__.py")
    assert task_runner(1, cluster.scheduler_address).address == cluster.scheduler_address
    missing = {"w2": {"sim2radar": "ImportError: ModuleNotFoundError: No module named 'sim2radar'",
                      "sim2radar.tasks": "/x/tasks/__init__.py",
                      "sim2radar.storage": "/x/storage/__init__.py"}}
    (problem,) = _worker_problems("tcp://h:8786", missing)
    assert "cannot import sim2radar " in problem and "dask worker tcp://h:8786" in problem
    with pytest.raises(ConnectionError, match="no Dask scheduler at tcp://127.0.0.1:9"):
        check_dask_workers("tcp://127.0.0.1:9", timeout_s=1)


def test_simulate_flow_on_dask_matches_threads(cluster, prefect_server, tmp_path,
                                               broken_scenes):
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.simulate import SimulateRequest, simulate_dataset
    from sim2radar.storage import ArtifactStore
    from sim2radar.storage.codecs import radar_frames_from_table
    from sim2radar.tasks.runner import RunOptions

    def read_points(root, key):
        return [f.points for f in radar_frames_from_table(
            ArtifactStore(root).read("radar_points", key))]

    scenes = [_plate(tmp_path, "near", 2.0), broken_scenes["unknown"]]
    dask_root, thread_root = tmp_path / "dask", tmp_path / "threads"
    request = SimulateRequest(scenes=[str(s) for s in scenes], store=str(dask_root),
                              dataset="d", run={"dask_address": cluster.scheduler_address})
    on_dask = run_flow(simulate_dataset, request=request)
    on_threads = run_flow(simulate_dataset, request=request.model_copy(
        update={"store": str(thread_root), "run": RunOptions(workers=1)}))
    for summary in (on_dask, on_threads):
        assert summary["counts"] == {"ok": 1, "skipped": 0, "failed": 1}
    # the work ran in the worker processes, each of which chose its Mitsuba variant itself
    states = _client_run(cluster, _mitsuba_state)
    assert len(states) == 2 and all(s["pid"] != os.getpid() for s in states.values())
    assert any(s["mitsuba"] and s["variant_cached"] == 1 for s in states.values())

    rows = {st: {r["scene_id"]: r for r in ArtifactStore(root).manifest("d").rows()}
            for st, root in (("dask", dask_root), ("threads", thread_root))}
    assert rows["dask"]["unknown_material"]["status"] == "failed"
    assert "unobtainium" in rows["dask"]["unknown_material"]["error"]
    d, t = rows["dask"]["near"], rows["threads"]["near"]
    assert d["status"] == "ok" and d["artifacts"] == t["artifacts"]
    key = d["artifacts"]["radar_points"]
    pd, pt = read_points(dask_root, key), read_points(thread_root, key)
    assert _same_points(pd[0], pt[0])  # the same cloud, computed in another process
    # physics survived the trip: the strongest return is the plate, at its range (2 m)
    strongest = pd[0][np.argmax(pd[0][:, 3])]
    assert abs(np.linalg.norm(strongest[:3]) - 2.0) < 0.1

    # second run through the deployment entrypoint (Prefect loads the file as a module of its
    # own; what reaches the workers must still unpickle there)
    before = _parquet_mtimes(dask_root)
    job = load_flow_from_entrypoint(f"{REPO}/flows/simulate.py:simulate_dataset")
    again = run_flow(job, request=request.model_dump(mode="json"))   # Failed (a scene failed)
    assert again["counts"] == {"ok": 0, "skipped": 1, "failed": 1}
    assert _parquet_mtimes(dask_root) == before
    rows = {r["scene_id"]: r for r in ArtifactStore(dask_root).manifest("d").rows()}
    assert rows["near"]["status"] == "skipped" and rows["near"]["attempts"] == 2


def test_generate_flow_on_dask_matches_threads(cluster, prefect_server, tmp_path):
    from sim2radar.datasets import OpenPCDetDataset
    from sim2radar.evaluate.reconstruction import chamfer_distance
    from sim2radar.flows._states import run_flow
    from sim2radar.flows.generate_dataset import GenerateRequest, generate_dataset
    from sim2radar.radar import load_radar_config
    from sim2radar.storage import ArtifactStore
    from sim2radar.tasks import dataset as td

    radar = load_radar_config("ti-mmwcas", ray_spacing_deg=0.5)
    spec = {"frames_per_world": 1, "radar": radar, "geometry": "both", "world": WORLD,
            "rig": RIG}
    args = dict(spec=spec, seeds=[5, 6, BROKEN_SEED], dataset="g")
    dask_root, thread_root = tmp_path / "dask", tmp_path / "threads"
    on_dask = run_flow(generate_dataset, request=GenerateRequest(
        store=str(dask_root / "store"), export_dir=str(dask_root / "opd"),
        run={"dask_address": cluster.scheduler_address}, **args))
    on_threads = run_flow(generate_dataset, request=GenerateRequest(
        store=str(thread_root / "store"), run={"workers": 1}, **args))
    for summary in (on_dask, on_threads):
        assert summary["counts"] == {"ok": 2, "skipped": 0, "failed": 1}
        assert summary["frame_counts"]["ok"] == 2
    by_seed = {st: {o.seed: o for o in td.outcomes_from_summary(s)}
               for st, s in (("dask", on_dask), ("threads", on_threads))}
    assert "seed" in by_seed["dask"][BROKEN_SEED].error
    for seed in (5, 6):
        fd, ft = by_seed["dask"][seed].parts, by_seed["threads"][seed].parts
        assert [f.artifacts for f in fd] == [f.artifacts for f in ft]
        for g in ("ground_truth", "reconstructed"):
            a = td.read_dataset_frame(dask_root / "store", fd[0].artifacts[f"dataset_frames/{g}"])
            b = td.read_dataset_frame(thread_root / "store",
                                      ft[0].artifacts[f"dataset_frames/{g}"])
            assert len(a.points) > 10 and np.array_equal(a.gt_boxes, b.gt_boxes)
            if g == "ground_truth":  # same meshes -> the same cloud and labels
                assert _same_points(a.points, b.points) and np.array_equal(a.boxes, b.boxes)
            else:  # reconstructed from a render in another process: float32 summation order
                # may move a segment boundary, so compare clouds and pseudo-labels loosely
                assert chamfer_distance(a.points, b.points) < 0.05
                assert 0.9 < len(a.points) / len(b.points) < 1.1
                assert abs(len(a.boxes) - len(b.boxes)) <= 1
    rows = {r["scene_id"]: r["status"] for r in ArtifactStore(dask_root / "store")
            .manifest("g").rows()}
    assert rows["world_000005_f000"] == "ok" and rows["world_000006"] == "ok"
    assert list(rows.values()).count("failed") == 1
    ids = OpenPCDetDataset(dask_root / "opd" / "ground_truth").split_ids("train")
    ids += OpenPCDetDataset(dask_root / "opd" / "ground_truth").split_ids("val")
    ids += OpenPCDetDataset(dask_root / "opd" / "ground_truth").split_ids("test")
    assert sorted(ids) == ["world_000005_f000", "world_000006_f000"]

    # second run through the deployment entrypoint (as `prefect deploy` runs it): all cached
    before = _parquet_mtimes(dask_root / "store")
    job = load_flow_from_entrypoint(f"{REPO}/flows/generate_dataset.py:generate_dataset")
    again = job(request={"spec": {**spec, "radar": radar.model_dump(mode="json")},
                         "first_seed": 5, "n_worlds": 2, "store": str(dask_root / "store"),
                         "dataset": "g", "run": {"dask_address": cluster.scheduler_address}})
    assert again["counts"] == {"ok": 0, "skipped": 2, "failed": 0}
    assert again["frame_counts"]["skipped"] == 2
    assert _parquet_mtimes(dask_root / "store") == before
