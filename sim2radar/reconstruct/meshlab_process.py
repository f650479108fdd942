"""pymeshlab's quadric decimation, and the worker process that runs it (stage 4b's simplifier).

:func:`decimate` is what :func:`sim2radar.reconstruct.meshing.simplify_mesh` computes.
pymeshlab is not thread-safe (two decimations on two threads of one process failed with
``std::bad_alloc``, then a double free), so meshing runs it in worker processes, one mesh at a
time each: this file run as a script,

    python -P .../sim2radar/reconstruct/meshlab_process.py

reads pickled ``(vertices, faces, target_faces)`` jobs from its standard input and writes a
pickled ``(True, (vertices, faces))`` or ``(False, exception)`` for each to its standard
output, until its input ends (its parent closed it, or died). It is started by path, not as
``-m sim2radar...``, so it imports NumPy and pymeshlab only, not the package (``-P``: nor this
folder's, which would shadow top-level modules of their names). Whatever pymeshlab
prints goes to standard error, never into the results. Ctrl-C is left to the parent, whose
exit ends the workers' input.
"""

from __future__ import annotations

import os
import pickle
import signal
import sys
from typing import BinaryIO

import numpy as np


def decimate(vertices: np.ndarray, faces: np.ndarray, target_faces: int
             ) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge-collapse decimation to about ``target_faces`` faces: ``(vertices (V, 3)
    float32, faces (F, 3) int32)`` (the options: :func:`~sim2radar.reconstruct.meshing.
    simplify_mesh`)."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int32)))
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=target_faces,
        preserveboundary=False,
        boundaryweight=10.0,
        preservenormal=True,
        planarquadric=True,
        qualitythr=0.3,
        autoclean=True,
    )
    out = ms.current_mesh()
    return out.vertex_matrix().astype(np.float32), out.face_matrix().astype(np.int32)


def serve(jobs: BinaryIO, results: BinaryIO) -> None:
    """Answer every job read from ``jobs`` on ``results`` (module doc) until ``jobs`` ends."""
    while True:
        try:
            vertices, faces, target_faces = pickle.load(jobs)
        except EOFError:
            return
        try:
            answer = (True, decimate(vertices, faces, target_faces))
        except Exception as exc:  # noqa: BLE001 - the parent raises it for its mesh
            answer = (False, exc)
        try:
            data = pickle.dumps(answer, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # noqa: BLE001 - an exception that does not pickle: its text
            data = pickle.dumps((False, RuntimeError(f"{type(answer[1]).__name__}: "
                                                     f"{answer[1]}")))
        results.write(data)
        results.flush()


def main() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    results = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # pymeshlab's prints (C or Python) go to standard error
    sys.stdout = sys.stderr
    serve(sys.stdin.buffer, results)


if __name__ == "__main__":
    main()
