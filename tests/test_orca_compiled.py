"""The compiled parts of the ORCA kernel against plain references: the bucket-grid neighbour
search against brute force, the compiled Minkowski merge against the numpy one, and the
circle benchmark's overlap measure for the round peers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmpark.control.orca import neighbours, pairs
from swarmpark.control.orca.shapes import minkowski_difference
from swarmpark.core.geometry import rotation

# A 0.25 m lattice: exact coordinates and differences, and many equal distances (ties).
coords = st.lists(
    st.tuples(st.integers(-120, 120), st.integers(-120, 120)).map(
        lambda p: (0.25 * p[0], 0.25 * p[1])
    ),
    min_size=1,
    max_size=60,
)


def brute_force(pos: np.ndarray, cut: float, max_nb: int, near: float):
    n = len(pos)
    nbr = np.full((n, max_nb), -1)
    for i in range(n):
        cand = []
        for j in range(n):
            if j == i:
                continue
            dx, dy = pos[j] - pos[i]
            d = math.sqrt(dx * dx + dy * dy)
            if d < cut:
                cand.append((d, dx, dy, j))
        cand.sort()
        for s, c in enumerate(cand[:max_nb]):
            nbr[i, s] = c[3]
    close = {(i, j) for i in range(n) for j in range(i + 1, n) if math.dist(pos[i], pos[j]) <= near}
    return nbr, close


@settings(max_examples=80, deadline=None)
@given(coords, st.floats(0.5, 20.0), st.integers(1, 12), st.floats(0.0, 5.0))
def test_grid_neighbours_equal_brute_force(points, cut, max_nb, near):
    pos = np.array(points, dtype=float)
    nbr, close = neighbours.grid_neighbours(pos, cut, max_nb, max_nb, near)
    want_nbr, want_close = brute_force(pos, cut, max_nb, near)
    assert nbr.tolist() == want_nbr.tolist()
    assert {tuple(p) for p in close.tolist()} == want_close
    # Distance ties are broken by relative position: the result follows the robots, not
    # their order (robots at the very same point are told apart by index only).
    if len(set(points)) < len(points):
        return
    perm = np.random.default_rng(len(points)).permutation(len(pos))
    nbr_p, _ = neighbours.grid_neighbours(pos[perm], cut, max_nb, max_nb, near)
    inv = np.argsort(perm)
    back = np.where(nbr_p >= 0, perm[np.maximum(nbr_p, 0)], -1)[inv]
    assert back.tolist() == nbr.tolist()


def test_grid_neighbours_with_robots_spread_far_apart_use_coarse_buckets():
    # Two clusters 10 km apart and a cut-off of 1 m: the grid must not have 10^8 buckets.
    rng = np.random.default_rng(0)
    pos = np.concatenate([rng.uniform(0, 3, (50, 2)), rng.uniform(0, 3, (50, 2)) + 1e4])
    nbr, close = neighbours.grid_neighbours(pos, 1.0, 10, 10, 0.5)
    want_nbr, want_close = brute_force(pos, 1.0, 10, 0.5)
    assert nbr.tolist() == want_nbr.tolist()
    assert {tuple(p) for p in close.tolist()} == want_close


@settings(max_examples=60, deadline=None)
@given(
    st.tuples(st.floats(0.2, 2.0), st.floats(0.2, 2.0), st.floats(-4, 4)),
    st.tuples(st.floats(0.2, 2.0), st.floats(0.2, 2.0), st.floats(-4, 4)),
    st.tuples(st.floats(-5, 5), st.floats(-5, 5)),
)
def test_compiled_minkowski_merge_equals_the_numpy_merge(ra, rb, offset):
    def rect(length, width, yaw):
        c = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * [length / 2, width / 2]
        return c @ rotation(yaw).T

    a, b = rect(*ra), rect(*rb)
    sx = np.ascontiguousarray(np.stack([b, a])[..., 0].T)
    sy = np.ascontiguousarray(np.stack([b, a])[..., 1].T)
    rx, ry = pairs.minkowski_pairs(
        sx, sy, np.array([0]), np.array([1]), np.array([offset[0]]), np.array([offset[1]])
    )
    ref = minkowski_difference(b[None], a[None])[0]
    assert np.array_equal(rx[:, 0], ref[:, 0] + offset[0])
    assert np.array_equal(ry[:, 0], ref[:, 1] + offset[1])


def test_peer_overlap_is_that_of_the_circumscribed_discs():
    peers = pytest.importorskip("swarmpark.apps.bench.peers")
    r = peers.PEER_RADIUS_M
    pos = np.array([[0.0, 0.0], [2.0 * r - 0.05, 0.0], [10.0, 0.0]])
    assert peers._max_overlap(pos) == pytest.approx(0.05)
    assert peers._max_overlap(pos[[0, 2]]) == 0.0
