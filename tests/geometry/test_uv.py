"""UV maps: checks, rasterisation into texels (fill rule, overlaps, mirrored islands), padding, automatic atlas.

References are geometric facts computed here independently: the texel centres of a square, areas in UV space,
barycentrics reproducing the centres."""
import numpy as np
import pytest

from meshshade.errors import MeshValidationError
from meshshade.geometry.procedural import icosphere
from meshshade.geometry.uv import automatic_atlas, check_uv, dilate, rasterise_uv, texel_uv

SQUARE = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], dtype=float)


@pytest.mark.parametrize("size", [(8, 8), (17, 5), (64, 64)])
def test_two_triangles_of_the_unit_square_cover_every_texel_once(size):
    W, H = size
    texel, face, bary, stats = rasterise_uv(SQUARE, W, H)
    np.testing.assert_array_equal(texel, np.arange(W * H))      # every texel, each once (the diagonal included)
    assert stats["uv_overlap_texels"] == 0
    p = np.einsum("ij,ijk->ik", bary, SQUARE[face])
    np.testing.assert_allclose(p, texel_uv(texel // W, texel % W, W, H), atol=1e-12)


def test_texel_rows_run_from_the_top():
    tri = np.array([[[0, 0.5], [1, 0.5], [1, 1]], [[0, 0.5], [1, 1], [0, 1]]])   # the upper half in v
    texel, _, _, _ = rasterise_uv(tri, 4, 4)
    np.testing.assert_array_equal(texel, np.arange(8))                           # rows 0 and 1 of the image


def test_mirrored_islands_are_rasterised_as_they_are():
    mirrored = SQUARE[:, [0, 2, 1]]                                              # opposite winding in UV
    assert check_uv(mirrored, 2)["uv_mirrored_faces"] == 2
    texel, face, bary, _ = rasterise_uv(mirrored, 16, 16)
    assert texel.size == 256
    np.testing.assert_allclose(np.einsum("ij,ijk->ik", bary, mirrored[face]),
                               texel_uv(texel // 16, texel % 16, 16, 16), atol=1e-12)


def test_overlapping_islands_first_face_wins_and_are_counted():
    uv = np.concatenate([SQUARE[:1], SQUARE[:1], SQUARE[1:]])
    texel, face, _, stats = rasterise_uv(uv, 32, 32)
    assert texel.size == 32 * 32
    assert not np.any(face == 1)                                  # the duplicate of face 0 got nothing
    assert stats["uv_overlap_texels"] == np.sum(face == 0) > 0


def test_coverage_follows_the_uv_area():
    rng = np.random.default_rng(3)
    for _ in range(20):
        tri = rng.random((1, 3, 2))
        d1, d2 = tri[0, 1] - tri[0, 0], tri[0, 2] - tri[0, 0]
        area = 0.5 * abs(d1[0] * d2[1] - d1[1] * d2[0])
        W = 512
        texel, _, _, _ = rasterise_uv(tri, W, W)
        perim = sum(np.linalg.norm(tri[0, i] - tri[0, (i + 1) % 3]) for i in range(3))
        assert abs(texel.size - area * W * W) <= perim * W + 4


@pytest.mark.parametrize("bad, words", [
    (np.full((2, 3, 2), np.nan), "non-finite"),
    (SQUARE + 1.5, "outside [0, 1]"),
    (SQUARE[:, :2], "expected (2, 3, 2)"),
])
def test_unusable_uvs_are_refused_in_one_line(bad, words):
    with pytest.raises(MeshValidationError) as e:
        check_uv(bad, 2)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_degenerate_uv_faces_get_no_texels_and_are_counted():
    uv = np.concatenate([SQUARE, [[[0.5, 0.5], [0.5, 0.5], [0.5, 0.5]]]])
    assert check_uv(uv, 3)["uv_degenerate_faces"] == 1
    _, face, _, _ = rasterise_uv(uv, 16, 16)
    assert not np.any(face == 2)


def test_padding_fills_rings_from_the_border_and_keeps_the_inside():
    """Two chessboard rings around one texel: the 5 x 5 square, every texel the nearest covered one's value."""
    img = np.zeros((9, 9, 3))
    mask = np.zeros((9, 9), bool)
    mask[4, 4] = True
    img[4, 4] = [1.0, 2.0, 3.0]
    out, filled = dilate(img, mask, 2)
    assert filled.sum() == 25 and filled[2:7, 2:7].all()          # two rings around the texel
    np.testing.assert_array_equal(out[filled], np.tile([1.0, 2.0, 3.0], (25, 1)))
    assert np.all(out[~filled] == 0.0)
    out0, filled0 = dilate(img, mask, 0)
    assert filled0.sum() == 1 and np.array_equal(out0, img)


def test_automatic_atlas_keeps_the_faces_and_does_not_overlap():
    V, F = icosphere(10.0, 2)
    uv, stats = automatic_atlas(V, F, size=256, padding=2)
    assert uv.shape == (F.shape[0], 3, 2) and stats["uv_charts"] >= 1
    check_uv(uv, F.shape[0])
    texel, face, _, rs = rasterise_uv(uv, 256, 256)
    assert rs["uv_overlap_texels"] == 0
    assert np.unique(face).size > 0.95 * F.shape[0]               # almost every face has texels at 256^2
    uv2, _ = automatic_atlas(V, F, size=256, padding=2)
    np.testing.assert_array_equal(uv, uv2)                          # deterministic


def test_padding_takes_the_nearest_island():
    img = np.zeros((1, 12, 1))
    mask = np.zeros((1, 12), bool)
    mask[0, 0], mask[0, 11] = True, True
    img[0, 0, 0], img[0, 11, 0] = 1.0, 2.0
    out, filled = dilate(img, mask, 4)
    np.testing.assert_array_equal(out[0, :, 0], [1, 1, 1, 1, 1, 0, 0, 2, 2, 2, 2, 2])
    np.testing.assert_array_equal(filled[0], [True] * 5 + [False] * 2 + [True] * 5)
