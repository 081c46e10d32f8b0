"""compare.py statistics on a synthetic pair, the split image, the CLI."""
import json

import numpy as np

from meshshade import io
from meshshade.cli.main import main
from meshshade.output.compare import compare_stats, relative_difference, split_image
from meshshade.geometry import procedural


def test_compare_stats_synthetic_pair():
    rng = np.random.default_rng(3)
    n = 1000
    b = np.repeat(rng.uniform(1.0, 2.0, n)[:, None], 3, axis=1)
    rel = np.linspace(-0.2, 0.1, n)
    a = b * (1 + rel)[:, None]
    b_low = b.copy()
    b_low[:10] = 1e-9  # below the floor: left out
    a[:10] = 5.0
    s = compare_stats(a, b_low, vertex_areas=np.full(n, 2.0), names=("A", "B"))
    r = np.abs(rel[10:])
    assert np.isclose(s["max_rel_diff"], r.max())
    assert np.isclose(s["mean_rel_diff"], r.mean())
    assert np.isclose(s["p95_rel_diff"], np.percentile(r, 95))
    assert s["vertices"]["count"] == n - 10
    assert np.allclose(s["total_exitance_W"]["A"], 2 * a.sum(0))
    img_a, img_b = a[:100].reshape(10, 10, 3), b_low[:100].reshape(10, 10, 3)
    s2 = compare_stats(a, b_low, pixel_a=img_a, pixel_b=img_b, pixel_mask=np.ones((10, 10), bool))
    assert np.isclose(s2["pixels"]["max_rel_diff"], np.abs(rel[10:100]).max())
    assert np.isnan(relative_difference(img_a, img_b)[0, 0])


def test_split_image_halves():
    a, b = np.zeros((4, 6, 3)), np.ones((4, 6, 3))
    s = split_image(a, b)
    assert np.all(s[:, :3] == 0) and np.all(s[:, 3:] == 1)


def test_cli_compare(tmp_path):
    V, F = procedural.icosphere(10.0, 3)
    io.write_ply(tmp_path / "s.ply", V, F)
    out = tmp_path / "cmp"
    rc = main(["compare", str(tmp_path / "s.ply"), "--material", "skin1", "--light", "beam:0,0,30:0,0,-1",
               "--models", "curved,dipole", "--width", "32", "--height", "32", "--spp", "1", "--out", str(out),
               "-q"])
    assert rc == 0
    for name in ("split.exr", "split.png", "heatmap.png", "stats.json", "curved.exr", "dipole.exr"):
        assert (out / name).is_file()
    st = json.loads((out / "stats.json").read_text())
    for k in ("max_rel_diff", "mean_rel_diff", "p95_rel_diff"):
        assert st[k] >= 0 and st["pixels"][k] >= 0
    assert set(st["total_exitance_W"]) == {"curved", "dipole"}
    assert main(["compare", str(tmp_path / "s.ply"), "--material", "skin1", "--light", "directional:0,0,-1",
                 "--models", "curved", "--out", str(out)]) == 2


def test_run_comparison_with_mc():
    from meshshade import Material
    from meshshade.output.compare import run_comparison
    from meshshade.geometry.mesh import Mesh
    from meshshade.light.samples import DirectionalLight

    V, F = procedural.icosphere(10.0, 2)
    mesh = Mesh.from_arrays(V, F)
    cmp = run_comparison(mesh, Material.preset("skin1"), [DirectionalLight((0, 0, -1))], ("dipole", "mc"),
                         width=24, height=24, spp=1, mc_photons=4000)
    st = cmp["stats"]
    assert st["models"] == ["dipole", "mc"] and st["vertices"]["count"] > 0
    assert cmp["split"][0].shape == (24, 24, 3)
