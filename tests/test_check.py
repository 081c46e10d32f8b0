"""`meshshade check`: check_mesh / format_check as functions, and the CLI with --json."""
import json
import warnings

import numpy as np
import pytest

from meshshade.check import check_mesh, format_check, report_to_json
from meshshade.cli.main import main
from meshshade.geometry.mesh import Mesh, MeshDefectWarning
from meshshade.geometry.procedural import icosphere, saddle_patch
from meshshade.io import write_ply
from meshshade.materials import Material


def _mesh(V, F):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshDefectWarning)
        return Mesh.from_arrays(V, F)


def test_check_mesh_sphere_sizes_and_curvature():
    mesh = _mesh(*icosphere(10.0, 3))
    mat = Material.preset("skin1")
    rep = check_mesh(mesh, mat)
    assert rep["mesh"]["n_vertices"] == 642 and rep["mesh"]["n_faces"] == 1280
    np.testing.assert_allclose(rep["mesh"]["size_mm"], 20.0, rtol=1e-12)
    k1_min = rep["curvature"]["k1_per_mm"]["min"]  # ~0.1017/mm: every vertex is at least this curved
    for ch, st in zip(rep["channels"], mat.sigma_t_prime):
        assert ch["largest_extent_in_transport_lengths"] == pytest.approx(20.0 * st)
        # first order needs radii of curvature >= 27-63 mm here (skin1 r, g, b): no vertex of a 10 mm sphere
        assert 1.0 / k1_min < ch["min_valid_radius_of_curvature_mm"]
        assert ch["fraction_first_order_valid"] == 0.0 and ch["fraction_first_order_valid_at_bake_cutoff"] == 0.0
        assert ch["resolution"] in ("resolved", "tail only", "unresolved")
        # it still holds near the entry point, out to the same distance at every vertex (uniform curvature, to
        # one step of the 64-interval grid up to the bake cutoff) and short of the 99 % radius where it fails
        dist = ch["first_order_distance_mm"]
        assert 0 < dist["min"] <= dist["max"] < ch["validity_rho_mm"]
        assert dist["max"] - dist["min"] <= ch["bake_cutoff_mm"] / 64 * (1 + 1e-12)
    c = rep["curvature"]
    assert c["k1_per_mm"]["percentiles"]["50"] == pytest.approx(0.1, rel=0.05)
    assert c["fraction_convex"] == 1.0 and c["fraction_saddle"] == 0.0
    assert rep["defects"]["closed"] and not rep["defects"]["warnings"]
    text = format_check(rep)
    assert "transport lengths" in text and "first order holds" in text
    json.loads(report_to_json(rep))


def test_check_first_order_validity_grows_with_radius():
    """First order holds on a big sphere and fails on a small one (same material, same mesh level)."""
    mat = Material.preset("skin1")
    small = check_mesh(_mesh(*icosphere(5.0, 3)), mat)["channels"][0]
    big = check_mesh(_mesh(*icosphere(500.0, 3)), mat)["channels"][0]
    assert small["fraction_first_order_valid"] == 0.0
    assert big["fraction_first_order_valid"] == 1.0
    assert big["first_order_distance_mm"]["min"] > small["first_order_distance_mm"]["max"]
    assert small["min_valid_radius_of_curvature_mm"] == pytest.approx(big["min_valid_radius_of_curvature_mm"])


def test_check_saddle_and_resolution():
    mesh = _mesh(*saddle_patch(0.1, 5.0, 33))
    rep = check_mesh(mesh, Material.preset("skin1"))
    assert rep["curvature"]["fraction_saddle"] > 0.9
    assert not rep["defects"]["closed"] and rep["defects"]["n_boundary_edges"] > 0
    assert rep["channels"][0]["resolution"] == "resolved"  # 0.37 mm edges vs z_r 1.3 mm


def test_check_without_material():
    rep = check_mesh(_mesh(*icosphere(10.0, 2)))
    assert "channels" not in rep
    assert "material: none given" in format_check(rep)


def test_check_flat_single_triangle_is_finite_json():
    rep = check_mesh(_mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 2]])),
                     Material.preset("marble"))
    assert rep["curvature"]["min_radius_of_curvature_mm"] == float("inf")
    data = json.loads(report_to_json(rep))  # inf -> null, never invalid JSON
    assert data["curvature"]["min_radius_of_curvature_mm"] is None


def test_check_cli_text_and_json(tmp_path, capsys):
    V, F = icosphere(0.01, 2)  # 0.02 m across, given in metres
    p = tmp_path / "s.ply"
    write_ply(p, V, F)
    before = p.read_bytes()
    js = tmp_path / "r.json"
    assert main(["check", str(p), "--units", "m", "--material", "marble", "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "20 x 20 x 20 mm" in out and "transport lengths" in out and f"wrote {js}" in out
    data = json.loads(js.read_text())
    assert data["mesh"]["mm_per_unit"] == 1000.0
    np.testing.assert_allclose(data["mesh"]["size_mm"], 20.0, rtol=1e-6)
    assert len(data["channels"]) == 3
    assert p.read_bytes() == before
    assert not list(tmp_path.glob(".*.tmp*"))


def test_check_cli_defects_in_report_not_warnings(tmp_path, capsys):
    V, F = icosphere(10.0, 2)
    p = tmp_path / "open.obj"
    p.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V.tolist())
                 + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F[3:].tolist()))
    assert main(["check", str(p), "--sigma-s-prime", "1", "--sigma-a", "0.01"]) == 0
    cap = capsys.readouterr()
    assert "open boundary" in cap.out and "NOT closed" in cap.out
    assert "open boundary" not in cap.err


def test_check_reports_bowtie_vertex_and_fallback(tmp_path, capsys):
    """Two tetrahedra mirrored through a shared vertex: the vertex's normals cancel, libigl would crash there;
    check names the non-manifold vertex and the vertex left out of the curvature fit. The CLI runs in a child
    (a regression would be a segmentation fault)."""
    import subprocess
    import sys

    T = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    Ft = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    V = np.vstack([T, -T[1:]])
    F = np.vstack([Ft, np.array([0, 4, 5, 6])[Ft][:, [0, 2, 1]]])
    p = write_ply(tmp_path / "bowtie.ply", V, F)
    out = tmp_path / "report.json"
    proc = subprocess.run([sys.executable, "-m", "meshshade.cli", "check", str(p), "--json", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-500:])
    assert "bow-tie" in proc.stdout and "1 without a tangent plane" in proc.stdout
    rep = json.loads(out.read_text())
    assert rep["defects"]["n_nonmanifold_vertices"] == 1
    assert rep["curvature"]["n_no_plane"] == 1 and rep["curvature"]["n_fallback"] == 7
