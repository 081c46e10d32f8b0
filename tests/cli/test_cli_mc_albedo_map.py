"""`meshshade mc --albedo-map FILE|mtl|vertex` (issue 49, docs/physics.md §17): the walk in the painted medium that
`meshshade bake --albedo-map` shades (the same reading of the paint, :func:`meshshade.cli.bake.painted_material`),
and the same clean refusals."""
import json

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.io import write_ply, write_png
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, simulate
from meshshade.painted import PaintedMaterial

SUN = "directional:0,0,-1"


def test_mc_walks_the_vertex_colours_of_a_ply(cli, tmp_path):
    V, F = icosphere(10.0, 2)
    colours = np.where(V[:, 2:3] > 0, [200, 120, 120], [120, 200, 120]).astype(np.uint8)
    write_ply(tmp_path / "ball.ply", V, F, vertex_colors=colours)
    rc, _, err = cli.run(["mc", tmp_path / "ball.ply", "--material", "skin1", "--albedo-map", "vertex", "--light",
                          SUN, "--photons", "4000", "--seed", "3", "--npz", tmp_path / "v.npz", "--out",
                          tmp_path / "v.ply", "--summary", tmp_path / "v.json", "--quiet"])
    assert rc == 0, err
    got = np.load(tmp_path / "v.npz")["radiance"]
    mesh = Mesh.from_arrays(np.asarray(V, dtype=np.float32).astype(np.float64), F)
    lin = np.where(colours / 255 <= 0.04045, colours / 255 / 12.92, ((colours / 255 + 0.055) / 1.055) ** 2.4)
    ref = simulate(mesh, PaintedMaterial(Material.preset("skin1"), colour=lin), DirectionalLight([0, 0, -1.0], 1.0),
                   MCOptions(photons=4000, seed=3))
    np.testing.assert_array_equal(got, ref.radiance)
    assert "painted" in json.loads((tmp_path / "v.json").read_text())["material"]


def test_mc_refuses_a_map_on_a_mesh_without_uvs(cli, tmp_path):
    V, F = icosphere(10.0, 1)
    write_ply(tmp_path / "ball.ply", V, F)
    write_png(tmp_path / "paint.png", np.full((8, 8, 3), 128, dtype=np.uint8))
    rc, _, err = cli.run(["mc", tmp_path / "ball.ply", "--material", "skin1", "--albedo-map", tmp_path / "paint.png",
                          "--light", SUN, "--photons", "1000", "--out", tmp_path / "o.ply", "--quiet"])
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "texture coordinates" in err, err
    assert not (tmp_path / "o.ply").exists()
