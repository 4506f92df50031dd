"""Plain-Python products of 4-vectors and 4 x 4 matrices (lists or tuples of rows).

The NLSOC law runs at every control step; numpy's per-call overhead (a few microseconds per
product) would dominate it, so its products are written out here for n = 4.  Each sum is
evaluated left to right, term by term, so a zero entry adds an exact zero and the result
is the same as skipping it.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["dot", "mat_vec", "vec_mat"]

Vector = Sequence[float]
Matrix = Sequence[Sequence[float]]


def dot(a: Vector, b: Vector) -> float:
    """``a' b`` of two 4-vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]


def mat_vec(M: Matrix, v: Vector) -> tuple[float, float, float, float]:
    """``M v`` for a 4 x 4 ``M``."""
    v0, v1, v2, v3 = v
    m0, m1, m2, m3 = M
    return (m0[0] * v0 + m0[1] * v1 + m0[2] * v2 + m0[3] * v3,
            m1[0] * v0 + m1[1] * v1 + m1[2] * v2 + m1[3] * v3,
            m2[0] * v0 + m2[1] * v1 + m2[2] * v2 + m2[3] * v3,
            m3[0] * v0 + m3[1] * v1 + m3[2] * v2 + m3[3] * v3)


def vec_mat(v: Vector, M: Matrix) -> tuple[float, float, float, float]:
    """``v' M`` (a row) for a 4 x 4 ``M``."""
    v0, v1, v2, v3 = v
    m0, m1, m2, m3 = M
    return (v0 * m0[0] + v1 * m1[0] + v2 * m2[0] + v3 * m3[0],
            v0 * m0[1] + v1 * m1[1] + v2 * m2[1] + v3 * m3[1],
            v0 * m0[2] + v1 * m1[2] + v2 * m2[2] + v3 * m3[2],
            v0 * m0[3] + v1 * m1[3] + v2 * m2[3] + v3 * m3[3])
