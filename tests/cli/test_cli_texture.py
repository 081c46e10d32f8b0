"""``meshshade bake --texture``: the files a texture bake writes, UVs read from OBJ/glTF/PLY, bad input refused.

What is checked against an independent route: the EXR and PNG read back by OpenImageIO, the OBJ's UVs read back by
meshshade's reader and by trimesh, the glTF by trimesh (Blender's importer in tests/blender)."""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.errors import MeshValidationError

from meshshade.geometry.procedural import box, icosphere, spherical_uv
from meshshade.geometry.uv import rasterise_uv
from meshshade.io import load_mesh, read_exr, read_mesh_arrays, write_obj
from meshshade.io.uv_maps import read_corner_uv, read_uv_map

SUN = ["--light", "directional:0,0,-1:1", "--material", "skin1", "--quiet"]


def _obj_with_uv(tmp_path, name="ball.obj", radius=5.0, level=2, uv=None):
    V, F = icosphere(radius, level)
    uv = spherical_uv(V, F) if uv is None else uv
    path = tmp_path / name
    write_obj(path, V, F, uv=uv)
    return path, V, F, uv


def test_obj_uvs_round_trip_exactly(tmp_path):
    path, V, F, uv = _obj_with_uv(tmp_path)
    faces, corner_uv = read_corner_uv(path)
    np.testing.assert_array_equal(corner_uv, uv)
    np.testing.assert_array_equal(faces, read_mesh_arrays(path)[1])
    np.testing.assert_array_equal(read_uv_map(path, load_mesh(path)), uv)
    import trimesh
    t = trimesh.load(path, process=False)          # an independent reader (it splits the vertices at seams)
    np.testing.assert_allclose(np.asarray(t.visual.uv)[np.asarray(t.faces)], uv, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(t.vertices)[np.asarray(t.faces)], V[F], rtol=0, atol=0)


def test_obj_quads_with_vt_are_fan_triangulated_like_the_geometry(tmp_path):
    text = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n")
    path = tmp_path / "quad.obj"
    path.write_text(text)
    faces, uv = read_corner_uv(path)
    np.testing.assert_array_equal(faces, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_array_equal(uv, [[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]])


def test_corners_follow_a_face_whose_winding_validation_repairs(tmp_path):
    V, F = box(10.0)
    F = F.copy()
    F[3] = F[3, [0, 2, 1]]                                                 # one face wound inside out in the file
    rng = np.random.default_rng(0)
    uv = rng.random((F.shape[0], 3, 2))
    path = tmp_path / "box.obj"
    write_obj(path, V, F, uv=uv)
    with pytest.warns(Warning):
        mesh = load_mesh(path)
    assert not np.array_equal(mesh.faces, F)
    got = read_uv_map(path, mesh)
    file_uv = {(f, tuple(F[f])): uv[f] for f in range(F.shape[0])}
    for f in range(F.shape[0]):                                            # each corner keeps its own UV
        ref = file_uv[(f, tuple(F[f]))]
        for c in range(3):
            k = int(np.flatnonzero(F[f] == mesh.faces[f, c])[0])
            np.testing.assert_array_equal(got[f, c], ref[k])


def test_ply_vertex_s_t_are_read(tmp_path):
    V, F = icosphere(5.0, 1)
    st = np.stack([(V[:, 0] + 5) / 10, (V[:, 1] + 5) / 10], axis=1)
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(V)}\nproperty double x\nproperty double y\n"
            f"property double z\nproperty double s\nproperty double t\nelement face {len(F)}\n"
            "property list uchar int vertex_indices\nend_header\n")
    body = "".join(" ".join(repr(float(x)) for x in (*v, *w)) + "\n" for v, w in zip(V, st))
    body += "".join("3 " + " ".join(str(int(i)) for i in f) + "\n" for f in F)
    path = tmp_path / "ball.ply"
    path.write_text(head + body)
    np.testing.assert_allclose(read_uv_map(path, load_mesh(path)), st[F], rtol=0, atol=0)


def test_an_obj_with_some_faces_unmapped_is_refused(tmp_path):
    path = tmp_path / "part.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nf 1/1 2/2 3/3\nf 1 3 4\n")
    with pytest.raises(MeshValidationError, match="1 of 2 triangles have no texture coordinates"):
        read_corner_uv(path)
    np.testing.assert_array_equal(read_mesh_arrays(path)[1], [[0, 1, 2], [0, 2, 3]])   # the geometry reads


def test_files_without_uvs_give_none(tmp_path):
    V, F = icosphere(5.0, 1)
    path = tmp_path / "plain.obj"
    write_obj(path, V, F)
    assert read_corner_uv(path) is None


def test_texture_bake_writes_exr_png_and_the_atlas(cli, tmp_path):
    V, F = icosphere(5.0, 2)
    mesh_path = tmp_path / "ball.obj"
    write_obj(mesh_path, V, F)                                              # no UVs: an automatic atlas
    out = tmp_path / "ball_tex.exr"
    rc, so, err = cli.run(["bake", mesh_path, *SUN, "--texture", out, "--texture-size", 64, "--padding", 2])
    assert rc == 0, err
    pixels, meta = read_exr(out)
    assert pixels.shape == (64, 64, 4)
    assert "W/mm^2" in meta["units"] and meta["uv_source"] == "xatlas" and "skin1" in meta["material"]
    import OpenImageIO as oiio
    png = oiio.ImageBuf(str(out.with_suffix(".png")))
    assert (png.spec().width, png.spec().height, png.spec().nchannels) == (64, 64, 4)
    atlas = out.with_suffix(".obj")
    mesh = load_mesh(atlas)
    np.testing.assert_allclose(mesh.vertices, V, atol=1e-12)                # the same mesh, in order
    uv = read_uv_map(atlas, mesh)
    texel, _, _, _ = rasterise_uv(uv, 64, 64)
    covered = np.zeros(64 * 64, bool)
    covered[texel] = True
    assert np.all(pixels.reshape(-1, 4)[covered, 3] == 1.0)               # the atlas's texels are the texture's
    assert np.all(pixels.reshape(-1, 4)[covered, :3] >= 0.0)
    assert pixels[..., :3].max() > 0


def test_texture_with_glb_binds_the_texture_as_emissive(cli, tmp_path):
    mesh_path, V, F, uv = _obj_with_uv(tmp_path)
    out = tmp_path / "tex.exr"
    rc, _, err = cli.run(["bake", mesh_path, *SUN, "--texture", out, "--texture-size", 32, "--out",
                          tmp_path / "ball.glb"])
    assert rc == 0, err
    assert not out.with_suffix(".obj").exists()                            # the mesh's own UVs: no atlas written
    import trimesh
    scene = trimesh.load(tmp_path / "ball.glb")
    geom = next(iter(scene.geometry.values()))
    assert geom.visual.material.emissiveTexture is not None
    assert geom.visual.material.emissiveTexture.size == (32, 32)
    # every glTF corner's UV is the file's corner UV (the seam's vertices split)
    glb = load_mesh(tmp_path / "ball.glb", units="m")
    got = read_uv_map(tmp_path / "ball.glb", glb)
    np.testing.assert_allclose(got, uv, atol=1e-7)
    # the mesh's vertices first and in order, then the seam copies of the vertices the extras name
    source = np.concatenate([np.arange(V.shape[0]), _seam_source(tmp_path / "ball.glb")])
    np.testing.assert_allclose(glb.vertices, V[source], atol=1e-4)         # float32 metres back to mm


@pytest.mark.parametrize("args, needle", [
    (["--texture-size", "3"], "texture size"),
    (["--padding", "-1"], "padding"),
    (["--texture-refine", "many"], "--texture-refine"),
])
def test_bad_texture_options_are_refused(cli, tmp_path, args, needle):
    mesh_path, *_ = _obj_with_uv(tmp_path)
    before = cli.snapshot(tmp_path)
    rc, _, err = cli.run(["bake", mesh_path, *SUN, "--texture", tmp_path / "t.exr", *args])
    cli.assert_clean_failure(rc, err, before, tmp_path, needle)


def test_bake_needs_an_output(cli, tmp_path):
    mesh_path, *_ = _obj_with_uv(tmp_path)
    before = cli.snapshot(tmp_path)
    rc, _, err = cli.run(["bake", mesh_path, *SUN])
    cli.assert_clean_failure(rc, err, before, tmp_path, "--out", "--texture")


def test_uvs_outside_the_unit_square_are_refused(cli, tmp_path):
    V, F = icosphere(5.0, 1)
    uv = spherical_uv(V, F) * 2.0                                           # a tiled map
    mesh_path, *_ = _obj_with_uv(tmp_path, level=1, uv=uv)
    before = cli.snapshot(tmp_path)
    rc, _, err = cli.run(["bake", mesh_path, *SUN, "--texture", tmp_path / "t.exr"])
    cli.assert_clean_failure(rc, err, before, tmp_path, "outside [0, 1]")


def test_the_atlas_beside_the_texture_may_not_replace_the_input(cli, tmp_path):
    V, F = icosphere(5.0, 1)
    write_obj(tmp_path / "t.obj", V, F)                                     # no UVs: the atlas would be t.obj
    before = cli.snapshot(tmp_path)
    rc, _, err = cli.run(["bake", tmp_path / "t.obj", *SUN, "--texture", tmp_path / "t.exr"])
    cli.assert_clean_failure(rc, err, before, tmp_path, "t.obj")


def test_a_mesh_with_uvs_may_share_the_texture_name(cli, tmp_path):
    _obj_with_uv(tmp_path, name="t.obj", level=1)
    rc, _, err = cli.run(["bake", tmp_path / "t.obj", *SUN, "--texture", tmp_path / "t.exr", "--texture-size", 16])
    assert rc == 0, err
    assert (tmp_path / "t.exr").exists() and (tmp_path / "t.png").exists()


def _seam_source(path):
    import json
    import struct
    data = path.read_bytes()
    n = struct.unpack("<I", data[12:16])[0]
    doc = json.loads(data[20:20 + n])
    return np.asarray(doc["meshes"][0]["primitives"][0]["extras"]["seam_vertex_source"], dtype=np.int64)
