"""The backward Riccati recursion of the paper's LOC (eqs. 5-7), written once.

The general case is the affine-LQ problem ``x(k+1) = A x(k) + B u(k) + c(k)`` with the cost
``x(N)' H x(N) / 2 + sum_{k<N} (x(k)' Q x(k) + u(k)' R u(k)) / 2`` (eq. 5 for c = 0).  In
steps to go ``j`` (time ``k = N - j``, ``c = c(k)``), with the value function
``V_j(x) = x' P_j x / 2 + p_j' x + s_j``::

    P_0 = H,  p_0 = 0,  s_0 = 0
    G    = R + B' P_{j-1} B
    F_j  = G^-1 B' P_{j-1} A                    (eq. 6: the LQR gain, independent of c)
    A_cl = A - B F_j                            (erratum 1: the paper prints A + B F)
    P_j  = A_cl' P_{j-1} A_cl + F_j' R F_j + Q  (eq. 7)
    kf_j = G^-1 B' (P_{j-1} c + p_{j-1})        (feed-forward; 0 when c = 0)
    d_cl = c - B kf_j                           (closed loop: x+ = A_cl x + d_cl)
    p_j  = A_cl' (P_{j-1} c + p_{j-1})
    s_j  = s_{j-1} + kf_j' R kf_j / 2 + d_cl' P_{j-1} d_cl / 2 + p_{j-1}' d_cl

and the optimal input with j steps to go is ``u = -F_j x - kf_j``.  (Setting the gradient
``R u + B'(P_{j-1}(Ax + Bu + c) + p_{j-1})`` to zero gives u; substituting it, the linear term
``F' R kf + A_cl'(P d_cl + p)`` reduces to ``A_cl'(P c + p)`` because ``F' G = A' P B``.)
The optimal cost from ``x(0)`` is ``V_N(x(0))`` (:func:`affine_lqr_cost`).

:func:`riccati_recursion` runs it; :func:`finite_horizon_lqr` is LOC's view (c = 0, stops at
the fixed point of P), :func:`affine_lqr` the exact optimum of :mod:`gcs.optimal_affine`.
Both return arrays in steps-to-go order, as python-control's ``dlqr`` returns ``K, S, E``.
"""

from __future__ import annotations

import numpy as np

from gcs.errors import DesignError

__all__ = ["check_lq_problem", "riccati_recursion", "finite_horizon_lqr", "affine_lqr", "affine_lqr_cost"]

#: Relative tolerance of the symmetry checks (the config reader's, so a config that loads designs).
_SYM_RTOL, _SYM_ATOL = 1e-9, 1e-12


def _is_horizon(N) -> bool:
    return not isinstance(N, bool) and isinstance(N, (int, np.integer)) and N >= 1


def _check_weight(name: str, mat: np.ndarray, n: int, *, definite: bool) -> None:
    if mat.shape != (n, n):
        raise DesignError(f"{name} matrix is the wrong shape: {mat.shape}, expected {(n, n)}")
    if not np.all(np.isfinite(mat)):
        raise DesignError(f"{name} has non-finite entries")
    symmetric = np.allclose(mat, mat.T, rtol=_SYM_RTOL, atol=_SYM_ATOL)
    eig = np.linalg.eigvalsh(mat).min() if symmetric else np.nan
    if definite:
        if not eig > 0:
            raise DesignError(f"{name} matrix is not symmetric positive definite")
        return
    if not symmetric:
        raise DesignError(f"{name} matrix is not symmetric")
    if eig < -1e-9 * max(1.0, np.abs(mat).max()):
        raise DesignError(f"{name} matrix is not positive semidefinite")


def _check_offset(c, N: int, n: int) -> np.ndarray | None:
    if c is None:
        return None
    c = np.asarray(c, float)
    if c.shape == (n,):
        c = np.broadcast_to(c, (N, n))
    elif c.shape != (N, n):
        raise DesignError(f"c has shape {c.shape}, expected ({n},) (constant) or ({N}, {n}) (one row per step k)")
    if not np.all(np.isfinite(c)):
        raise DesignError("c has non-finite entries")
    return c


def check_lq_problem(A, B, Q, R, H, N, c=None):
    """Validate and convert an (affine-)LQ problem; returns ``a, b, q, r, h, N, c`` as float arrays.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m), or (n,) for m = 1
    Q, H : array_like, shape (n, n)
        Symmetric positive semidefinite.
    R : array_like, shape (m, m)
        Symmetric positive definite.
    N : int
        Horizon in steps, >= 1.
    c : array_like, shape (n,) or (N, n), or None
        Affine term (constant, or one row per step in time order); None: no affine term.

    Returns
    -------
    tuple
        ``(a, b, q, r, h, N, c)``; ``c`` is None or shape (N, n).

    Raises
    ------
    gcs.errors.DesignError (a ValueError)
        Wrong shapes, non-finite entries, Q/H not symmetric positive semidefinite, R not
        symmetric positive definite, N not an integer >= 1.
    """
    a, b = np.asarray(A, float), np.asarray(B, float)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise DesignError(f"A matrix must be square (n, n), got shape {a.shape}")
    n = a.shape[0]
    if b.ndim == 1:
        b = b.reshape(-1, 1)
    if b.ndim != 2 or b.shape[0] != n or b.shape[1] < 1:
        raise DesignError(f"B matrix is the wrong shape: {b.shape}, expected ({n}, m)")
    for name, mat in (("A", a), ("B", b)):
        if not np.all(np.isfinite(mat)):
            raise DesignError(f"{name} has non-finite entries")
    if not _is_horizon(N):
        raise DesignError(f"horizon N must be an integer >= 1, got {N!r}")
    q, r, h = (np.atleast_2d(np.asarray(x, float)) for x in (Q, R, H))
    _check_weight("Q", q, n, definite=False)
    _check_weight("H", h, n, definite=False)
    _check_weight("R", r, b.shape[1], definite=True)
    return a, b, q, r, h, int(N), _check_offset(c, int(N), n)


def riccati_recursion(a, b, q, r, h, N: int, c: np.ndarray | None = None, *, rtol: float | None = None):
    """The backward recursion of the module docstring on validated arrays (see :func:`check_lq_problem`).

    Parameters
    ----------
    a, b, q, r, h : ndarray
        Shapes (n, n), (n, m), (n, n), (m, m), (n, n).
    N : int
    c : ndarray, shape (N, n), or None
        Affine term in time order; None: plain LQR (``kf``, ``p``, ``s`` are then 0).
    rtol : float or None
        Only without ``c``: once ``max|P_j - P_{j-1}| <= rtol max|P_j|`` the recursion has reached
        its fixed point and the remaining entries repeat the last ones.  None: run all N steps.

    Returns
    -------
    F : ndarray, shape (N, m, n)
        ``F[j - 1]`` is the gain with j steps to go.
    kf : ndarray, shape (N, m)
    P : ndarray, shape (N + 1, n, n)
    p : ndarray, shape (N + 1, n)
    s : ndarray, shape (N + 1,)
    """
    if rtol is not None and c is not None:
        raise ValueError("rtol (stopping at the fixed point) needs c = None")
    n, m = b.shape
    F, kf = np.empty((N, m, n)), np.zeros((N, m))
    P, p, s = np.empty((N + 1, n, n)), np.zeros((N + 1, n)), np.zeros(N + 1)
    P[0] = h
    bt = b.T
    for j in range(1, N + 1):
        Pj = P[j - 1]
        G = r + bt @ Pj @ b
        f = np.linalg.solve(G, bt @ Pj @ a)                     # eq. 6
        acl = a - b @ f                                        # erratum 1
        pn = acl.T @ Pj @ acl + f.T @ r @ f + q                # eq. 7
        F[j - 1], P[j] = f, 0.5 * (pn + pn.T)
        if c is not None:
            ck = c[N - j]
            w = Pj @ ck + p[j - 1]
            kf[j - 1] = fj = np.linalg.solve(G, bt @ w)
            dcl = ck - b @ fj
            p[j] = acl.T @ w
            s[j] = s[j - 1] + 0.5 * fj @ r @ fj + 0.5 * dcl @ Pj @ dcl + p[j - 1] @ dcl
        elif rtol is not None and np.max(np.abs(P[j] - Pj)) <= rtol * np.max(np.abs(P[j])):
            F[j:], P[j + 1:] = f, P[j]
            break
    return F, kf, P, p, s


def finite_horizon_lqr(A, B, Q, R, H, N: int, *, rtol: float = 1e-14) -> tuple[np.ndarray, np.ndarray]:
    """Finite-horizon discrete LQR gain table (LOC, eqs. 5-7 with erratum 1).

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q, H : array_like, shape (n, n)
        Stage and terminal state weights, symmetric positive semidefinite.
    R : array_like, shape (m, m)
        Input weight, symmetric positive definite.
    N : int
        Horizon in steps, >= 1.
    rtol : float
        Once ``|P(j) - P(j-1)| <= rtol |P(j)|`` the recursion has reached its
        fixed point and the remaining entries repeat the last gain.

    Returns
    -------
    F : ndarray, shape (N, m, n)
        ``F[j - 1]`` is the gain with j steps to go; apply ``u(k) = -F[N - k - 1] x(k)``.
    P : ndarray, shape (N + 1, n, n)
        Cost-to-go matrices, ``P[0] = H``; the optimal cost from x(0) is ``x' P[N] x / 2``.
    """
    a, b, q, r, h, N, _ = check_lq_problem(A, B, Q, R, H, N)
    F, _, P, _, _ = riccati_recursion(a, b, q, r, h, N, rtol=rtol)
    return F, P


def affine_lqr(A, B, c, Q, R, H, N: int):
    """Exact finite-horizon optimum of an affine-LQ problem with a time-varying offset.

    Minimises ``x(N)' H x(N) / 2 + sum_{k<N} (x(k)' Q x(k) + u(k)' R u(k)) / 2`` subject to
    ``x(k+1) = A x(k) + B u(k) + c(k)`` over unconstrained inputs (the module docstring).

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m) (or (n,) for m = 1)
    c : array_like, shape (n,) or (N, n), or None
        Affine term: constant, or ``c[k]`` for the step k -> k + 1 in **time order**
        (k = 0 .. N-1); None means 0 (plain LQR).
    Q, H : array_like, shape (n, n)
        Stage and terminal state weights, symmetric positive semidefinite.
    R : array_like, shape (m, m)
        Input weight, symmetric positive definite.
    N : int
        Horizon in steps, >= 1.

    Returns
    -------
    K : ndarray, shape (N, m, n)
        Feedback gains in **steps-to-go order** (as :func:`finite_horizon_lqr`):
        ``K[j - 1]`` with j steps to go.
    k_ff : ndarray, shape (N, m)
        Feed-forward, same order.  The optimal input at time k is
        ``u(k) = -K[N - k - 1] x(k) - k_ff[N - k - 1]``.
    P : ndarray, shape (N + 1, n, n)
    p : ndarray, shape (N + 1, n)
    s : ndarray, shape (N + 1,)
        Value function with j steps to go, ``V_j(x) = x' P[j] x / 2 + p[j]' x + s[j]``;
        ``P[0] = H``, ``p[0] = 0``, ``s[0] = 0``.  The optimal cost from x(0) is ``V_N(x(0))``.

    Raises
    ------
    gcs.errors.DesignError (a ValueError)
        As :func:`check_lq_problem`.
    """
    a, b, q, r, h, N, cc = check_lq_problem(A, B, Q, R, H, N, c)
    return riccati_recursion(a, b, q, r, h, N, cc)


def affine_lqr_cost(P, p, s, x0, steps: int | None = None) -> float:
    """Optimal cost ``V_j(x0) = x0' P[j] x0 / 2 + p[j]' x0 + s[j]`` from :func:`affine_lqr`.

    Parameters
    ----------
    P : array_like, shape (N + 1, n, n)
    p : array_like, shape (N + 1, n)
    s : array_like, shape (N + 1,)
    x0 : array_like, shape (n,)
        Initial error state.
    steps : int or None
        Steps to go j (0 .. N); None = N, the whole horizon.

    Returns
    -------
    float
    """
    P, p, s = np.asarray(P, float), np.asarray(p, float), np.asarray(s, float)
    if P.ndim != 3 or P.shape[1] != P.shape[2]:
        raise DesignError(f"P has shape {P.shape}, expected (N + 1, n, n)")
    N1, n = P.shape[0], P.shape[1]
    if p.shape != (N1, n):
        raise DesignError(f"p has shape {p.shape}, expected {(N1, n)}")
    if s.shape != (N1,):
        raise DesignError(f"s has shape {s.shape}, expected ({N1},)")
    x0 = np.asarray(x0, float)
    if x0.shape != (n,):
        raise DesignError(f"x0 has shape {x0.shape}, expected ({n},)")
    j = N1 - 1 if steps is None else steps
    if isinstance(j, bool) or not isinstance(j, (int, np.integer)) or not 0 <= j < N1:
        raise DesignError(f"steps must be an integer in 0 .. {N1 - 1}, got {steps!r}")
    return float(0.5 * x0 @ P[j] @ x0 + p[j] @ x0 + s[j])
