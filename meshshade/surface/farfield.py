"""Clustered far-field summation of the planar dipole with a guaranteed relative error.

The bake sums ``M(x_o) = sum_i Phi_i R(|x_o - x_i|)`` over entry samples i. Pairs closer than ``r_near`` (chord)
stay in the geodesic near zone (gather.py); the pairs with ``r_near < |x_o - x_i| <= cutoff`` are summed
here with the dipole of the chord distance. Following Jensen & Buhler 2002 ("A rapid hierarchical rendering
technique for translucent materials", SIGGRAPH), the sources are clustered in a tree and a cluster far enough
from the receiver is replaced by its total power at its power-weighted centroid.

Cluster expansion and error bound (derivation in farfield_loops.py; tested in tests/surface/test_farfield.py): a
cluster with total power P, power-weighted centroid c, second-moment tensor Q, radius a about c and mean cubed
radius m3, seen from a receiver at distance d > a, is replaced by the second-order Taylor expansion of the
dipole about c (the first-order term vanishes at the power-weighted centroid):

    sum_j P_j R(|x - y_j|) ~ P R(d) + 1/2 [G''(d) (c - x)^T Q (c - x) + G'(d) tr Q]      (R = G(r^2/2))

with remainder at most ``P m3/6 * T(d - a)``, where T(r) bounds the dipole's third derivatives beyond r. A
cluster is used whole only when it lies wholly inside the annulus r_near < r <= cutoff and this remainder is at
most ``rel_tol * P R(d + a)``, a lower bound of the cluster's exact contribution (R decreases). Clusters wholly
inside r_near or beyond the cutoff are skipped, the others opened; leaves are summed pair by pair with the exact
masks. A share ``budget_share`` of rel_tol may instead be spent as a global budget: a cluster that fails
that test, or one that straddles the cutoff (the sources beyond it then add at most P R(cutoff)), is still used
whole if its bound is at most ``budget_share * rel_tol * L * P / P_total``, with L = (sum so far) - (bounds so
far) <= M_far_exact a running lower bound (nearest clusters are visited first). Summed over the clusters,

    |M_far(x) - M_far_exact(x)|  <=  stats["error_bound"](x)  <=  rel_tol * M_far_exact(x)

for every receiver and channel (up to float64 rounding). Measured maximum errors are 40-100x below the
guaranteed bound (tools/benchmarks/bench_farfield.py), because a cluster's third-order terms largely cancel. Relative to
the total exitance the error is at most ``rel_tol`` times the far field's share of it (see
:func:`far_field_radius`).

Cost: the expansion is accepted when (a/d)^3 ~ rel_tol (1/r^3 regime) or (mu a)^3 ~ rel_tol (exponential
regime), so a receiver evaluates O(log(cutoff/r_near) / rel_tol^(2/3)) clusters, plus the leaves that straddle
the two radii (a ring of leaves: O(sqrt(n)) pairs on a surface). Pair by pair: O(k_cutoff) pairs per receiver.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from meshshade.errors import ParameterError
from meshshade.kernels.dipole import dipole_cutoff_radii
from meshshade.materials import Material
from meshshade.pacing import run_in_blocks
from meshshade.surface.farfield_loops import (accumulate_pairs, kd_permutation, node_moments, node_ranges,
                                                  traverse, tree_depth)

#: default guaranteed relative tolerance on the far-field sum (measured maximum errors are 40-100x below it)
DEFAULT_REL_TOL = 0.1
#: share of rel_tol spent as a global budget (running lower bound of M times the cluster's power share)
DEFAULT_BUDGET_SHARE = 0.25
#: sources per leaf (16 beat 8 and 32 on 10k-40k vertex spheres: fewer node visits, more exact pairs)
DEFAULT_LEAF_SIZE = 16
#: default share of the dipole's energy left to the far field when choosing r_near (far_field_radius; the bake's
#: ``far_tol``): 0.1 gives r_near = 9-16 transport lengths for marble and milk, 2.3-5.1 for skin1
DEFAULT_FAR_TOL = 0.1
#: candidate pairs per chunk in the pairwise sum (memory ~ 24 bytes per pair)
PAIRWISE_PAIRS_PER_CHUNK = 4_000_000
#: receivers per block of the processing order (k-d leaves, shuffled across threads)
RECEIVER_BLOCK = 32


def _points(name, value) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ParameterError(f"{name} must be an (n, 3) array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} must be finite")
    return np.ascontiguousarray(arr)


def _power(value, k) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 1:
        arr = np.repeat(arr[:, None], 3, axis=1)
    if arr.shape != (k, 3):
        raise ParameterError(f"source power must be (k,) or (k, 3) with k = {k} sources, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ParameterError("source power must be finite and >= 0 [W]")
    return np.ascontiguousarray(arr)


def _radii(name, value, *, allow_zero) -> np.ndarray:
    try:
        arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).copy()
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number or three numbers (mm), got {value!r}") from None
    bad = ~np.isfinite(arr) | (arr < 0) | (~allow_zero & (arr == 0))
    if np.any(bad):
        raise ParameterError(f"{name} must be finite and {'>=' if allow_zero else '>'} 0 mm, got {arr.tolist()}")
    return arr


def _channel_params(material: Material):
    """(sigma_t' [1/mm], alpha', mu = sigma_tr/sigma_t', z_v [optical]) per channel, (3,) each."""
    p = material.medium.jensen
    return (np.ascontiguousarray(material.sigma_t_prime, dtype=np.float64), np.ascontiguousarray(p.albedo_prime),
            np.ascontiguousarray(p.mu), np.ascontiguousarray(p.z_v))


@dataclass(frozen=True, eq=False)
class SourceTree:
    """A balanced k-d tree over entry samples with per-channel cluster moments (build with :meth:`build`).

    positions : (k, 3) float64 mm and power : (k, 3) float64 W, in tree order; ``perm[t]`` is the input row of
    tree row t. Nodes form an implicit complete binary tree (children 2i+1, 2i+2; leaves from ``first_leaf``),
    node i covering rows ``node_lo[i]:node_hi[i]``. Per node and channel: ``node_power`` (W), ``node_centroid``
    (power-weighted, mm), ``node_radius`` (largest distance from the centroid to a source of the node, mm),
    ``node_q`` (second-moment tensor about the centroid, (xx, yy, zz, xy, xz, yz), W mm^2) and ``node_m3``
    (power-weighted mean cubed distance from the centroid, mm^3).
    """

    positions: np.ndarray
    power: np.ndarray
    perm: np.ndarray
    leaf_size: int
    depth: int
    node_lo: np.ndarray
    node_hi: np.ndarray
    node_power: np.ndarray
    node_centroid: np.ndarray
    node_radius: np.ndarray
    node_q: np.ndarray
    node_m3: np.ndarray

    @classmethod
    def build(cls, positions, power, *, leaf_size: int = DEFAULT_LEAF_SIZE) -> "SourceTree":
        """Tree over ``positions`` (k, 3) mm with ``power`` (k,) or (k, 3) W >= 0; O(k log^2 k), numba."""
        pos = _points("source positions", positions)
        pw = _power(power, len(pos))
        if int(leaf_size) < 1:
            raise ParameterError(f"leaf_size must be >= 1, got {leaf_size}")
        k = len(pos)
        depth = int(tree_depth(max(k, 1), int(leaf_size)))
        lo, hi = node_ranges(k, depth)
        perm = kd_permutation(pos, depth, lo, hi) if k else np.zeros(0, np.int64)
        pos_t, pw_t = np.ascontiguousarray(pos[perm]), np.ascontiguousarray(pw[perm])
        P, C, A, Q, M3 = node_moments(pos_t, pw_t, lo, hi)
        return cls(pos_t, pw_t, perm, int(leaf_size), depth, lo, hi, P, C, A, Q, M3)

    @property
    def n_sources(self) -> int:
        return len(self.positions)

    @property
    def first_leaf(self) -> int:
        return (1 << self.depth) - 1

    def __repr__(self) -> str:
        return (f"SourceTree({self.n_sources} sources, depth {self.depth}, leaf_size {self.leaf_size}, "
                f"total power {self.node_power[0].round(6).tolist() if self.n_sources else [0.0] * 3} W)")


def _as_tree(sources, leaf_size) -> SourceTree:
    if isinstance(sources, SourceTree):
        return sources
    try:
        positions, power = sources
    except (TypeError, ValueError):
        raise ParameterError("sources must be a SourceTree or a (positions (k, 3), power (k, 3)) pair") from None
    return SourceTree.build(positions, power, leaf_size=leaf_size)


def _receiver_order(recv) -> np.ndarray:
    """A spatially coherent processing order of the receivers (k-d order), for cache locality."""
    n = len(recv)
    if n < 2:
        return np.arange(n)
    depth = int(tree_depth(n, RECEIVER_BLOCK))
    lo, hi = node_ranges(n, depth)
    # a writable C copy (mesh.vertices is read-only): the same compiled specialisation as the source trees' calls
    order = kd_permutation(np.array(recv, dtype=np.float64, order="C"), depth, lo, hi)
    # the traversals take consecutive blocks of this order, one block per thread at a time: shuffle the k-d leaves
    # (fixed seed) so that each block mixes cheap and expensive regions while each leaf keeps its locality
    first = (1 << depth) - 1
    leaf_of_row = np.repeat(np.arange(1 << depth), hi[first:] - lo[first:])
    rank = np.random.default_rng(0).permutation(1 << depth)
    return order[np.argsort(rank[leaf_of_row], kind="stable")]


def far_field_exitance(sources, receivers, material: Material, r_near_mm, cutoff_mm, *,
                       rel_tol: float = DEFAULT_REL_TOL, leaf_size: int = DEFAULT_LEAF_SIZE,
                       budget_share: float = DEFAULT_BUDGET_SHARE, near_ratio=None) -> tuple[np.ndarray, dict]:
    """Clustered far-field exitance ``M[x, c] = sum_i P_ic R_c(|x - y_i|)`` over ``r_near_c < |x - y_i| <= cutoff_c``.

    Parameters
    ----------
    sources : SourceTree, or (positions (k, 3) mm, power (k,) or (k, 3) W >= 0)
    receivers : (n, 3) float64 mm
    material : Material (per-channel dipole: R_c(r) = dipole_profile(r sigma_t') sigma_t'^2, 1/mm^2)
    r_near_mm : float or (3,) >= 0; pairs at chord distance <= r_near belong to the near zone (excluded)
    cutoff_mm : float or (3,) > 0; pairs beyond are excluded
    rel_tol : float >= 0; guaranteed ``|M - M_exact| <= rel_tol * M_exact`` per receiver and channel (module
        docstring); 0 gives the exact sum (only clusters of coincident sources are merged)
    budget_share : float in [0, 1); this share of rel_tol is spent as a global budget: a cluster that fails the
        own-contribution test, or straddles the cutoff (whose sources beyond it then add at most P R(cutoff)),
        is still used whole when its bound is within ``budget_share rel_tol L P / P_total``, L being the running
        lower bound (sum so far minus bounds so far) of M_exact; the guarantee is unchanged
    near_ratio : None, or (nlog (3, m), l0, step): the near field's factor N(r) (docs/physics.md eq. (80)) as
        ln N on the grid l0 + i step of ln(r sigma_t') (NearFieldFactors.log_ratio_table / slope_table): each
        channel's dipole is multiplied by it (per pair at leaves, at the centroid distance for a cluster, whose
        bound is scaled alike: the guarantee then holds for the dipole times N at the centroid)

    Returns
    -------
    M_far : (n, 3) float64 W/mm^2
    stats : dict with ``pairs_exact`` (pair-channel kernel evaluations at leaves), ``clusters_accepted``
        (cluster-channel evaluations; ``clusters_from_budget`` of them by the budget), ``nodes_visited``,
        ``error_bound`` ((n, 3) W/mm^2, the sum of the accepted clusters' bounds, <= rel_tol * M_exact),
        ``seconds``, ``rel_tol``.
    """
    t0 = time.perf_counter()
    recv = _points("receivers", receivers)
    rn = _radii("r_near_mm", r_near_mm, allow_zero=True)
    cut = _radii("cutoff_mm", cutoff_mm, allow_zero=False)
    if not (np.isfinite(rel_tol) and rel_tol >= 0):
        raise ParameterError(f"rel_tol must be finite and >= 0, got {rel_tol}")
    if not (0 <= budget_share < 1):
        raise ParameterError(f"budget_share must lie in [0, 1), got {budget_share}")
    tree = _as_tree(sources, leaf_size)
    st, al, mu, zv = _channel_params(material)
    if tree.n_sources == 0 or len(recv) == 0:
        M, E, counts = np.zeros((len(recv), 3)), np.zeros((len(recv), 3)), np.zeros((len(recv), 4), np.int64)
    else:
        order = _receiver_order(recv)
        nl = _near_ratio_args(near_ratio)

        def block(a, b):
            return traverse(recv, order[a:b], tree.positions, tree.power, tree.node_lo, tree.node_hi,
                            tree.first_leaf, tree.node_power, tree.node_centroid, tree.node_radius, tree.node_q,
                            tree.node_m3, rn, cut, st, al, mu, zv, float(rel_tol), float(budget_share), *nl)

        res = run_in_blocks(block, len(recv), min_block=64)   # serial loops on the pacing threads
        back = np.empty_like(order)   # the row of each receiver in the traversal's order
        back[order] = np.arange(order.size)
        M, E, counts = (np.concatenate([r[i] for r in res])[back] for i in range(3))
    tot = counts.sum(axis=0)
    stats = {"pairs_exact": int(tot[0]), "clusters_accepted": int(tot[1]), "nodes_visited": int(tot[2]),
             "clusters_from_budget": int(tot[3]),
             "error_bound": E, "rel_tol": float(rel_tol), "seconds": time.perf_counter() - t0}
    return M, stats


def _near_ratio_args(near_ratio):
    """(nlog (3, m), l0, step) for the kernels; a (3, 0) placeholder without the near field."""
    if near_ratio is None:
        return np.zeros((3, 0)), 0.0, 1.0
    nlog, l0, step = near_ratio
    return np.ascontiguousarray(nlog, dtype=np.float64), float(l0), float(step)


def far_field_exitance_pairwise(sources, receivers, material: Material, r_near_mm, cutoff_mm, *,
                                rel_tol: float = 0.0, leaf_size: int = DEFAULT_LEAF_SIZE,
                                near_ratio=None) -> tuple[np.ndarray, dict]:
    """Exact twin of :func:`far_field_exitance` (same signature; ``rel_tol`` and ``leaf_size`` are ignored).

    Candidate pairs come from scipy's cKDTree (``sparse_distance_matrix`` between a receiver chunk and the
    sources, within max(cutoff)), in chunks of about ``PAIRWISE_PAIRS_PER_CHUNK`` pairs; the masks
    ``r_near_c < r <= cutoff_c`` and the kernel are applied in numba with the same distance formula as the
    clustered sum. Cost O(n k_cutoff), never all pairs. stats: ``pairs_exact``, ``candidate_pairs``, ``seconds``.
    """
    t0 = time.perf_counter()
    recv = _points("receivers", receivers)
    rn = _radii("r_near_mm", r_near_mm, allow_zero=True)
    cut = _radii("cutoff_mm", cutoff_mm, allow_zero=False)
    if isinstance(sources, SourceTree):
        pos, pw = sources.positions, sources.power
    else:
        try:
            positions, power = sources
        except (TypeError, ValueError):
            raise ParameterError("sources must be a SourceTree or a (positions (k, 3), power (k, 3)) pair") from None
        pos = _points("source positions", positions)
        pw = _power(power, len(pos))
    st, al, mu, zv = _channel_params(material)
    n = len(recv)
    M = np.zeros((n, 3))
    n_eval = n_cand = 0
    if n and len(pos):
        src_tree = cKDTree(pos)
        nr = _near_ratio_args(near_ratio)
        radius = float(cut.max()) * (1.0 + 1e-9)
        order = _receiver_order(recv)
        a, chunk = 0, 256
        while a < n:
            idx = order[a:a + chunk]
            pairs = cKDTree(recv[idx]).sparse_distance_matrix(src_tree, radius, output_type="ndarray")
            # (whether coincident pairs are listed does not matter: r = 0 <= r_near is never far field)
            ii, jj = idx[pairs["i"]], pairs["j"].astype(np.int64)
            n_eval += accumulate_pairs(M, recv, pos, pw, ii, jj, rn, cut, st, al, mu, zv, *nr)
            n_cand += len(ii)
            per = max(len(ii) / len(idx), 1.0)
            a += len(idx)
            chunk = int(np.clip(PAIRWISE_PAIRS_PER_CHUNK / per, 16, 1 << 20))
    return M, {"pairs_exact": int(n_eval), "candidate_pairs": int(n_cand), "seconds": time.perf_counter() - t0}


def check_far_tol(far_tol) -> float:
    """``far_tol`` as a float in (0, 1), the far field's share of the dipole's energy; ParameterError otherwise."""
    if not (0 < far_tol < 1):
        raise ParameterError(f"far_tol must lie in (0, 1), got {far_tol}")
    return float(far_tol)


def far_field_radius(material: Material, far_tol: float = DEFAULT_FAR_TOL) -> np.ndarray:
    """(3,) mm: per channel, the radius beyond which the dipole's closed-form tail holds ``far_tol`` of its total.

    The r_near policy for the bake: with ``r_near = far_field_radius(material, far_tol)`` the far field carries
    exactly ``far_tol`` of the exitance of a uniformly lit plane (about that much on smooth lit surfaces; all of
    it in shadowed regions), so the guaranteed far-field error ``rel_tol`` is about ``rel_tol * far_tol`` of the
    local exitance where the surface is lit.
    """
    return dipole_cutoff_radii(check_far_tol(far_tol), sigma_t_prime=material.sigma_t_prime,
                               albedo_prime=material.albedo_prime, eta=material.eta)
