"""The names a mesh file gives its faces (issue 49, :mod:`meshshade.io.part_names`): an OBJ's usemtl and g names
in the reader's face order (polygons fan-triangulated in place), a GLB's material names per primitive in the
order the mesh reader concatenates them."""
import numpy as np
import pytest

from meshshade.errors import MeshValidationError
from meshshade.io import read_mesh_arrays
from meshshade.io.part_names import read_face_names

OBJ = """v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
f 1 2 3
usemtl red
g top
f 1 2 3 4
usemtl blue
f 1 2 5
g side
f 2 3 5
usemtl red
f 3 4 5
"""


def test_obj_usemtl_and_group_names_follow_the_face_order(tmp_path):
    path = tmp_path / "m.obj"
    path.write_text(OBJ)
    V, F = read_mesh_arrays(path)
    assert F.shape[0] == 6                            # the quad is two triangles, in place
    names = read_face_names(path, F.shape[0])
    assert list(names) == ["red", "blue", "top", "side"]
    np.testing.assert_array_equal(names["red"], [0, 1, 1, 0, 0, 1])
    np.testing.assert_array_equal(names["blue"], [0, 0, 0, 1, 1, 0])
    np.testing.assert_array_equal(names["top"], [0, 1, 1, 1, 0, 0])
    np.testing.assert_array_equal(names["side"], [0, 0, 0, 0, 1, 1])


def test_obj_names_for_another_face_count_are_refused(tmp_path):
    path = tmp_path / "m.obj"
    path.write_text(OBJ)
    with pytest.raises(MeshValidationError, match="6 faces, the mesh has 7"):
        read_face_names(path, 7)


def test_a_format_without_names_names_nothing(tmp_path):
    path = tmp_path / "m.off"
    path.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    assert read_face_names(path, 1) == {}


def test_glb_material_names_per_primitive(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    from trimesh.visual.material import PBRMaterial
    from trimesh.visual.texture import TextureVisuals

    scene = trimesh.Scene()
    for k, (name, n) in enumerate((("skin", 2), ("stone", 3))):
        V = np.random.default_rng(k).normal(size=(n + 2, 3))
        F = np.stack([np.zeros(n, int), np.arange(1, n + 1), np.arange(2, n + 2)], axis=1)
        mesh = trimesh.Trimesh(V, F, process=False, visual=TextureVisuals(material=PBRMaterial(name=name)))
        scene.add_geometry(mesh, geom_name=f"g{k}")
    path = tmp_path / "m.glb"
    path.write_bytes(scene.export(file_type="glb"))
    _, F = read_mesh_arrays(path)
    names = read_face_names(path, F.shape[0])
    assert set(names) == {"skin", "stone"}
    assert names["skin"].sum() == 2 and names["stone"].sum() == 3
    assert not (names["skin"] & names["stone"]).any()
    assert names["skin"][:2].all()                     # the reader concatenates the primitives in file order


@pytest.mark.parametrize("with_uv", [False, True])
def test_write_obj_groups_read_back_as_the_parts(tmp_path, with_uv):
    """write_obj's groups are usemtl runs that read_face_names reads back face for face; the mesh is unchanged."""
    from meshshade.geometry.procedural import icosphere, spherical_uv
    from meshshade.io import load_mesh, read_face_names, write_obj

    V, F = icosphere(5.0, 1)
    part = (np.arange(len(F)) // 7) % 3
    path = write_obj(tmp_path / "parts.obj", V, F, uv=spherical_uv(V, F) if with_uv else None,
                     groups=(["skin", "stone", "eye"], part))
    names = read_face_names(path, len(F))
    assert list(names) == ["skin", "stone", "eye"]
    for i, name in enumerate(["skin", "stone", "eye"]):
        np.testing.assert_array_equal(names[name], part == i)
    mesh = load_mesh(path)
    np.testing.assert_array_equal(mesh.faces, F)
    with pytest.raises(ValueError, match="without blanks"):
        write_obj(tmp_path / "bad.obj", V, F, groups=(["a b", "c", "d"], part))
