"""Tests for sim2radar/mesh.py: mesh validation, PLY/OBJ round trips, scene listings."""

import numpy as np
import pytest

from sim2radar.mesh import MaterialMesh, MeshFileError, box_mesh, load_mesh, load_scene, save_ply


def test_box_mesh_is_closed_and_outward():
    box = box_mesh([1.0, 2.0, 3.0], [2.0, 4.0, 6.0], material="metal")
    assert box.area_m2 == pytest.approx(2 * (2 * 4 + 4 * 6 + 2 * 6))
    centroids = box.triangles.mean(axis=1)
    outward = np.einsum("ij,ij->i", box.face_normals, centroids - [1.0, 2.0, 3.0])
    assert (outward > 0).all()


def test_ply_binary_roundtrip_and_obj(tmp_path):
    box = box_mesh([0, 0, 0], [1, 1, 1], material="wood")
    loaded = load_mesh(save_ply(box, tmp_path / "b.ply"), "wood")
    np.testing.assert_allclose(loaded.vertices, box.vertices)
    np.testing.assert_array_equal(loaded.faces, box.faces)
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1 2/2 3/3 4/4\n")
    quad = load_mesh(obj, "glass")
    assert quad.faces.shape == (2, 3) and quad.area_m2 == pytest.approx(1.0)


def test_ascii_ply(tmp_path):
    p = tmp_path / "tri.ply"
    p.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    assert load_mesh(p, "concrete").area_m2 == pytest.approx(0.5)


def test_bad_inputs_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match="face indices"):
        MaterialMesh(np.zeros((3, 3)), [[0, 1, 5]], material="metal")
    with pytest.raises(MeshFileError, match="not found"):
        load_mesh(tmp_path / "nope.ply", "metal")
    bad = tmp_path / "bad.ply"
    bad.write_text("hello")
    with pytest.raises(MeshFileError, match="not a PLY"):
        load_mesh(bad, "metal")
    save_ply(box_mesh([0, 0, 0], [1, 1, 1], material="metal"), tmp_path / "ok.ply")
    listing = tmp_path / "scene.yaml"
    listing.write_text("meshes:\n  - file: ok.ply\n")
    with pytest.raises(MeshFileError, match=r"meshes\[0\]: missing field 'material'"):
        load_scene(listing)
    listing.write_text("meshes:\n  - file: ok.ply\n    material: metal\n    semantic: door\n")
    (mesh,) = load_scene(listing)
    assert mesh.semantic == "door" and mesh.name == "ok"
