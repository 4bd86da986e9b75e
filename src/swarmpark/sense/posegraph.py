"""A 2-D pose graph: keyframe poses joined by relative-pose measurements, optimized by
sparse nonlinear least squares.

The back end of graph SLAM (Grisetti, Kümmerle, Stachniss and Burgard 2010, "A tutorial on
graph-based SLAM"): odometry / scan-matching edges between consecutive keyframes and
loop-closure edges between a keyframe and an older one it matched; the optimization spreads the
drift accumulated around a loop over the whole loop. The residual of an edge ``i -> j`` with
measurement ``z`` (``j`` in ``i``'s frame) is ``[R_i^T (t_j - t_i) - z_xy, wrap(th_j - th_i -
z_th)]``, weighted by the square root of the edge's information matrix; its Jacobian is
analytic and sparse, and :func:`scipy.optimize.least_squares` (trust-region reflective with a
sparse LSQR inner solver) does the rest. The first node is held fixed (the gauge).

>>> g = PoseGraph()
>>> for k in range(4):  # a square loop of 1 m sides whose odometry over-turns by 0.05 rad
...     _ = g.add_node([0.0, 0.0, 0.0] if k == 0 else None)
>>> for k in range(3):
...     g.add_edge(k, k + 1, [1.0, 0.0, np.pi / 2 + 0.05])
>>> g.initialize_from_edges()
>>> g.add_edge(3, 0, [1.0, 0.0, np.pi / 2])  # closing the loop
>>> report = g.optimize()
>>> np.round(g.poses[2, :2], 1).tolist()  # odometry alone: (0.95, 1.0)
[1.0, 1.0]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

from swarmpark.core.geometry import wrap_angle

__all__ = ["PoseGraph", "Edge", "DEFAULT_INFORMATION"]

#: Information (inverse covariance) of an edge without one: 5 cm and about 1 degree.
DEFAULT_INFORMATION = np.diag([1 / 0.05**2, 1 / 0.05**2, 1 / 0.02**2])


@dataclass(frozen=True)
class Edge:
    """A relative-pose measurement: ``j``'s pose in ``i``'s frame, with its information."""

    i: int
    j: int
    z: np.ndarray
    sqrt_info: np.ndarray  # upper-triangular L^T with L L^T = information
    loop: bool = False


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array(
        [a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_angle(a[2] + b[2])]
    )


class PoseGraph:
    """Keyframe poses ``(N, 3)`` and the edges between them."""

    def __init__(self) -> None:
        self._poses: list[np.ndarray | None] = []
        self.edges: list[Edge] = []

    @property
    def poses(self) -> np.ndarray:
        if any(p is None for p in self._poses):
            raise ValueError("pose graph: some nodes have no initial pose (initialize_from_edges)")
        return np.array(self._poses, float).reshape(-1, 3)

    def __len__(self) -> int:
        return len(self._poses)

    def add_node(self, pose=None) -> int:
        """Add a keyframe with an initial pose (``None``: filled in by
        :meth:`initialize_from_edges`); returns its index."""
        p = None if pose is None else np.asarray(pose, float).reshape(3)
        if p is not None and not np.all(np.isfinite(p)):
            raise ValueError(f"pose graph: node pose must be finite (got {p.tolist()})")
        self._poses.append(p)
        return len(self._poses) - 1

    def set_pose(self, k: int, pose) -> None:
        self._poses[k] = np.asarray(pose, float).reshape(3)

    def add_edge(self, i: int, j: int, z, information=None, *, loop: bool = False) -> None:
        """Add the measurement ``z`` = pose of ``j`` in ``i``'s frame ``(dx, dy, dth)``."""
        n = len(self._poses)
        if not (0 <= i < n and 0 <= j < n and i != j):
            raise ValueError(f"pose graph: edge ({i}, {j}) needs two different nodes of {n}")
        z = np.asarray(z, float).reshape(3)
        info = DEFAULT_INFORMATION if information is None else np.asarray(information, float)
        if info.shape != (3, 3) or not np.all(np.isfinite(info)) or not np.all(np.isfinite(z)):
            raise ValueError(f"pose graph: edge ({i}, {j}) has a non-finite or bad measurement")
        try:
            sqrt_info = np.linalg.cholesky(info).T
        except np.linalg.LinAlgError:
            raise ValueError(
                f"pose graph: edge ({i}, {j}) information is not positive definite"
            ) from None
        self.edges.append(Edge(i, j, z, sqrt_info, loop))

    def initialize_from_edges(self) -> None:
        """Chain missing initial poses along edges from nodes that have one (odometry)."""
        changed = True
        while changed:
            changed = False
            for e in self.edges:
                if self._poses[e.i] is not None and self._poses[e.j] is None:
                    self._poses[e.j] = _compose(self._poses[e.i], e.z)
                    changed = True

    # ------------------------------------------------------------------ optimization

    def _residuals(self, x: np.ndarray, idx: tuple[np.ndarray, ...]) -> np.ndarray:
        i, j, z, sq = idx
        p = x.reshape(-1, 3)
        pi, pj = p[i], p[j]
        c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
        dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
        e = np.column_stack(
            [
                c * dx + s * dy - z[:, 0],
                -s * dx + c * dy - z[:, 1],
                wrap_angle(pj[:, 2] - pi[:, 2] - z[:, 2]),
            ]
        )
        return np.einsum("kab,kb->ka", sq, e).ravel()

    def _jacobian(self, x: np.ndarray, idx: tuple[np.ndarray, ...]) -> csr_matrix:
        i, j, _, sq = idx
        p = x.reshape(-1, 3)
        pi, pj = p[i], p[j]
        c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
        dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
        m = len(i)
        ji = np.zeros((m, 3, 3))  # d e / d p_i
        jj = np.zeros((m, 3, 3))  # d e / d p_j
        ji[:, 0, 0], ji[:, 0, 1], ji[:, 0, 2] = -c, -s, -s * dx + c * dy
        ji[:, 1, 0], ji[:, 1, 1], ji[:, 1, 2] = s, -c, -c * dx - s * dy
        ji[:, 2, 2] = -1.0
        jj[:, 0, 0], jj[:, 0, 1] = c, s
        jj[:, 1, 0], jj[:, 1, 1] = -s, c
        jj[:, 2, 2] = 1.0
        ji = np.einsum("kab,kbc->kac", sq, ji)
        jj = np.einsum("kab,kbc->kac", sq, jj)
        rows = np.repeat(np.arange(3 * m).reshape(m, 3, 1), 3, axis=2)
        cols_i = 3 * i[:, None, None] + np.arange(3)[None, None, :]
        cols_j = 3 * j[:, None, None] + np.arange(3)[None, None, :]
        cols_i = np.broadcast_to(cols_i, (m, 3, 3))
        cols_j = np.broadcast_to(cols_j, (m, 3, 3))
        data = np.concatenate([ji.ravel(), jj.ravel()])
        r = np.concatenate([rows.ravel(), rows.ravel()])
        cidx = np.concatenate([cols_i.ravel(), cols_j.ravel()])
        jac = csr_matrix((data, (r, cidx)), shape=(3 * m, 3 * len(p)))
        return jac[:, 3:]  # node 0 is fixed (the gauge)

    def optimize(self, *, max_iterations: int = 50, tolerance: float = 1e-8) -> dict:
        """Optimize every pose but the first; returns ``{"iterations", "cost_before",
        "cost_after", "edges", "loop_edges"}``."""
        x0 = self.poses.ravel()
        if not self.edges or len(x0) <= 3:
            return {
                "iterations": 0,
                "cost_before": 0.0,
                "cost_after": 0.0,
                "edges": 0,
                "loop_edges": 0,
            }
        idx = (
            np.array([e.i for e in self.edges]),
            np.array([e.j for e in self.edges]),
            np.array([e.z for e in self.edges]),
            np.array([e.sqrt_info for e in self.edges]),
        )
        anchor = x0[:3].copy()

        def fun(free):
            return self._residuals(np.concatenate([anchor, free]), idx)

        def jac(free):
            return self._jacobian(np.concatenate([anchor, free]), idx)

        before = 0.5 * float(np.sum(fun(x0[3:]) ** 2))
        sol = least_squares(
            fun,
            x0[3:],
            jac=jac,
            method="trf",
            tr_solver="lsmr",
            x_scale="jac",
            max_nfev=max_iterations,
            ftol=tolerance,
            xtol=tolerance,
            gtol=tolerance,
        )
        out = np.concatenate([anchor, sol.x]).reshape(-1, 3)
        out[:, 2] = wrap_angle(out[:, 2])
        self._poses = list(out)
        return {
            "iterations": int(sol.nfev),
            "cost_before": before,
            "cost_after": float(sol.cost),
            "edges": len(self.edges),
            "loop_edges": sum(e.loop for e in self.edges),
        }
