"""Pose-graph optimization: a drifting loop is pulled back onto the truth by one loop-closure
edge; the analytic Jacobian matches finite differences; bad edges are refused."""

import numpy as np
import pytest

from swarmpark.sense.posegraph import PoseGraph


def _relative(a, b):
    c, s = np.cos(a[2]), np.sin(a[2])
    d = b[:2] - a[:2]
    return np.array(
        [c * d[0] + s * d[1], -s * d[0] + c * d[1], np.angle(np.exp(1j * (b[2] - a[2])))]
    )


def _loop_truth(n=60, radius=8.0):
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([radius * np.cos(th), radius * np.sin(th), th + np.pi / 2])


def test_a_loop_with_drifting_odometry_closes_onto_the_truth():
    rng = np.random.default_rng(1)
    truth = _loop_truth()
    g = PoseGraph()
    g.add_node(truth[0])
    for _ in truth[1:]:
        g.add_node(None)
    bias = np.array([0.0, 0.0, 0.004])  # odometry over-turns: the loop does not close
    for k in range(len(truth) - 1):
        z = _relative(truth[k], truth[k + 1]) + bias + rng.normal(0, [0.01, 0.01, 0.002])
        g.add_edge(k, k + 1, z)
    g.initialize_from_edges()
    drift = np.linalg.norm(g.poses[-1, :2] - truth[-1, :2])
    # Loop closures: the last keyframes matched against the first ones.
    for a, b in ((len(truth) - 1, 0), (len(truth) - 2, 1)):
        g.add_edge(a, b, _relative(truth[a], truth[b]), loop=True)
    report = g.optimize()
    err = np.linalg.norm(g.poses[:, :2] - truth[:, :2], axis=1)
    assert drift > 1.0  # the loop really drifted
    assert err.max() < 0.15, err.max()
    assert report["loop_edges"] == 2 and report["cost_after"] < report["cost_before"]


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(2)
    g = PoseGraph()
    for _ in range(5):
        g.add_node(rng.normal(0, 2, 3))
    for i, j in ((0, 1), (1, 2), (2, 3), (3, 4), (4, 0), (1, 3)):
        g.add_edge(i, j, rng.normal(0, 1, 3), np.diag(rng.uniform(1, 50, 3)))
    x = g.poses.ravel()
    idx = (
        np.array([e.i for e in g.edges]),
        np.array([e.j for e in g.edges]),
        np.array([e.z for e in g.edges]),
        np.array([e.sqrt_info for e in g.edges]),
    )
    jac = g._jacobian(x, idx).toarray()
    h = 1e-6
    num = np.zeros_like(jac)
    for k in range(3, len(x)):
        d = np.zeros_like(x)
        d[k] = h
        num[:, k - 3] = (g._residuals(x + d, idx) - g._residuals(x - d, idx)) / (2 * h)
    np.testing.assert_allclose(jac, num, atol=1e-5)


def test_bad_edges_are_refused_with_the_reason():
    g = PoseGraph()
    g.add_node([0, 0, 0])
    g.add_node([1, 0, 0])
    with pytest.raises(ValueError, match=r"edge \(0, 0\) needs two different nodes of 2"):
        g.add_edge(0, 0, [0, 0, 0])
    with pytest.raises(ValueError, match=r"edge \(0, 1\) has a non-finite"):
        g.add_edge(0, 1, [np.nan, 0, 0])
    with pytest.raises(ValueError, match="not positive definite"):
        g.add_edge(0, 1, [1, 0, 0], -np.eye(3))
    with pytest.raises(ValueError, match="node pose must be finite"):
        g.add_node([np.inf, 0, 0])
