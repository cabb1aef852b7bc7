"""Pose refinement: translations that join neighbouring wall chains (paper 3.3).

A quadratic program over one 2D translation per piece (the first stays put) minimises the
squared gaps between each piece's target and the next piece's source, subject to the
paper's junction constraints:

* parallel junction: the two walls are collinear (equal offset) and neither overruns the
  other's far end;
* perpendicular junction: neither wall end passes the other wall's line.

Strict inequalities get a small margin. OSQP solves it; its status is checked because an
infeasible or unsolved problem returns a meaningless x.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import osqp
from scipy import sparse

from services.placement import Piece, rot90
from services.types import FloatArray

__all__ = ["Refinement", "refine_translations"]

_MARGIN = 1e-3  # m, turns the paper's strict inequalities into solvable ones
_UNIT = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])


@dataclass(frozen=True)
class Refinement:
    """Refined translations.

    translations: (n, 2) float64, site position of each piece's source, loop order.
    status: "solved", or "fallback: <reason>" when the unrefined placement is kept.
    violation_before, violation_after: the largest junction-constraint violation (m) of the
    unrefined and the refined translations. Gaps along a continuing wall are not violations:
    the two collinear walls simply join; the loop is closed when no constraint is violated.
    """

    translations: FloatArray
    status: str
    violation_before: float
    violation_after: float


def _junction_rows(
    sites: list[FloatArray], pieces: Sequence[Piece], rotations: Sequence[int], n: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Objective (as least squares J t = g) and constraints l <= A t <= u."""
    dim = 2 * n
    j_rows, g_vals, a_rows, lows, highs = [], [], [], [], []
    for i in range(n):
        k = (i + 1) % n
        q, q_prev = sites[i][-1], sites[i][-2]
        p, p_next = sites[k][0], sites[k][1]
        d_i = _UNIT[(pieces[i].directions[-1] + rotations[i]) % 4]
        d_k = _UNIT[(pieces[k].directions[0] + rotations[k]) % 4]
        for axis in (0, 1):
            row = np.zeros(dim)
            row[2 * i + axis], row[2 * k + axis] = 1.0, -1.0
            j_rows.append(row)
            g_vals.append(p[axis] - q[axis])

        def diff(vec: FloatArray, i: int = i, k: int = k) -> FloatArray:
            """Row of vec . (t_k - t_i)."""
            row = np.zeros(dim)
            row[2 * k : 2 * k + 2] += vec
            row[2 * i : 2 * i + 2] -= vec
            return row

        if np.allclose(d_i, d_k):
            normal = np.array([-d_i[1], d_i[0]])
            a_rows.append(diff(normal))  # offsets equal
            lows.append(normal @ (q - p))
            highs.append(normal @ (q - p))
            longest = max(np.linalg.norm(q - q_prev), np.linalg.norm(p_next - p))
            a_rows.append(diff(d_i))  # no overrun
            lows.append(longest + _MARGIN - d_i @ (p_next - q_prev))
            highs.append(np.inf)
        elif abs(d_i @ d_k) < 0.5:
            a_rows.append(diff(d_i))  # q stays before the next wall's line
            lows.append(d_i @ (q - p) + _MARGIN)
            highs.append(np.inf)
            a_rows.append(diff(d_k))  # p starts past this wall's line
            lows.append(d_k @ (q - p) + _MARGIN)
            highs.append(np.inf)
    return (np.array(j_rows), np.array(g_vals), np.array(a_rows), np.array(lows), np.array(highs))


def refine_translations(
    pieces: Sequence[Piece], rotations: Sequence[int], translations: FloatArray
) -> Refinement:
    """Refine the placement's translations with the constrained QP.

    Parameters
    ----------
    pieces : pieces in loop order.
    rotations : quarter turns per piece, loop order.
    translations : (n, 2) site position of each piece's source from the placement.
    """
    n = len(pieces)
    sites = [
        p.keypoints @ rot90(r).T + t
        for p, r, t in zip(pieces, rotations, translations, strict=True)
    ]
    if n < 2:
        return Refinement(translations.copy(), "solved", 0.0, 0.0)
    J, g, A, lo, hi = _junction_rows(sites, pieces, rotations, n)
    before = _violation(A, lo, hi, np.zeros(2 * n))
    # Gauge: the first piece does not move.
    gauge = np.zeros((2, 2 * n))
    gauge[0, 0] = gauge[1, 1] = 1.0
    A = np.vstack([A, gauge]) if len(A) else gauge
    lo = np.concatenate([lo, [0.0, 0.0]])
    hi = np.concatenate([hi, [0.0, 0.0]])
    P = sparse.csc_matrix(J.T @ J + 1e-9 * np.eye(2 * n))
    q = -J.T @ g
    solver = osqp.OSQP()
    solver.setup(
        P,
        q,
        sparse.csc_matrix(A),
        lo,
        hi,
        verbose=False,
        eps_abs=1e-7,
        eps_rel=1e-7,
        max_iter=20000,
        polishing=True,
    )
    result = solver.solve()
    status = str(result.info.status)
    if status not in ("solved", "solved inaccurate") or result.x is None:
        return Refinement(translations.copy(), f"fallback: {status}", before, before)
    x = np.asarray(result.x, dtype=np.float64)
    return Refinement(translations + x.reshape(n, 2), "solved", before, _violation(A, lo, hi, x))


def _violation(A: FloatArray, lo: FloatArray, hi: FloatArray, x: FloatArray) -> float:
    """Largest amount by which A x leaves [lo, hi]; the gauge rows are included."""
    ax = A @ x
    return float(max(0.0, np.max(lo - ax), np.max(ax - hi)))
