"""Levenberg-Marquardt fits: scipy's ``least_squares(method="lm")`` call of
MINPACK without its wrapper (the fits' residuals are a few hundred numbers,
and the wrapper's per-call work was a measurable share of a recovery)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

try:  # MINPACK's lmder, as least_squares(method="lm") calls it
    from scipy.optimize import _minpack
    from scipy.optimize._lsq.least_squares import FROM_MINPACK_TO_COMMON, TERMINATION_MESSAGES
except ImportError:  # pragma: no cover - a scipy that moved them: least_squares itself
    _minpack = None


def lm_fit(resid, p0, jac, x_scale=None, ftol: float = 1e-8, xtol: float = 1e-8, gtol: float = 1e-8,
           max_nfev: int | None = None) -> OptimizeResult:
    """``least_squares(resid, p0, jac=jac, x_scale=x_scale, method="lm",
    ftol=ftol, xtol=xtol, gtol=gtol, max_nfev=max_nfev)`` (scipy 1.16 on:
    ``x_scale`` None is ``"jac"``, MINPACK's own scaling): the same MINPACK
    call (lmder, ``diag = 1 / x_scale``), on the same points, with the same
    residuals and Jacobians, each evaluated once a point as least_squares'
    VectorFunction keeps them (its start's first; the end's Jacobian again
    when the last point evaluated was another), without its wrapper:
    measured 3-5% of a recovery's CPU on recover_speed.py's 8 shots (1,500
    residuals and 800 Jacobians a run).  The fields set: ``x``, ``cost``,
    ``fun``, ``jac``, ``status``, ``success``, ``message``.  Raises
    ValueError where least_squares does (a NaN start, residuals not finite
    at the start, fewer residuals than parameters).

    Parameters
    ----------
    resid, jac : callable
        Residuals (shape (m,)) and their Jacobian (m, n) at a point.
    p0 : array_like, shape (n,)
        Start.
    x_scale : array_like, shape (n,), optional
        Each parameter's scale (its units); None: MINPACK's scaling by the
        Jacobian's columns.
    ftol, xtol, gtol : float
        Tolerances, as least_squares'.
    max_nfev : int, optional
        Residual evaluations allowed (default ``100 n``).
    """
    x0 = np.atleast_1d(np.asarray(p0, dtype=float)).astype(float)
    if x_scale is not None:
        x_scale = np.asarray(x_scale, dtype=float)
    if _minpack is None:  # pragma: no cover
        return least_squares(resid, x0, jac=jac, x_scale="jac" if x_scale is None else x_scale, method="lm",
                             ftol=ftol, xtol=xtol, gtol=gtol, max_nfev=max_nfev)
    if np.isnan(x0).any():
        raise ValueError("Initial guess is outside of provided bounds")  # least_squares' check: NaN is outside
    last = {"x": x0.copy(), "f": None, "J": None}  # the last point asked for, and what is known there

    def at(x):  # np.array_equal's test (elementwise ==), without its overhead
        if not (x.shape == last["x"].shape and bool((x == last["x"]).all())):
            last.update(x=np.array(x, dtype=float), f=None, J=None)

    def fun(x):
        at(x)
        if last["f"] is None:
            last["f"] = np.atleast_1d(resid(last["x"].copy()))
        return last["f"].copy()

    def jacobian(x):
        at(x)
        if last["J"] is None:
            last["J"] = np.atleast_2d(jac(last["x"].copy()))
        return last["J"].copy()

    f0 = fun(x0)
    jacobian(x0)
    if not np.all(np.isfinite(f0)):
        raise ValueError("Residuals are not finite in the initial point.")
    if f0.size < x0.size:
        raise ValueError("Method 'lm' doesn't work when the number of residuals is less than the number of "
                         "variables.")
    diag = None if x_scale is None else 1 / x_scale
    _zero_past_jacobian(f0.size, x0.size)
    x, info, status = _minpack._lmder(fun, jacobian, x0.copy(), (), True, False, ftol, xtol, gtol,
                                      100 * x0.size if max_nfev is None else max_nfev, 100.0, diag)
    f = info["fvec"]
    status = FROM_MINPACK_TO_COMMON[status]
    return OptimizeResult(x=x, cost=0.5 * np.dot(f, f), fun=f, jac=jacobian(x), status=status,
                          message=TERMINATION_MESSAGES[status], success=status > 0)


def _zero_past_jacobian(m: int, n: int) -> None:
    """Leave zeros in the heap block MINPACK's Jacobian is about to get.

    scipy's C MINPACK (1.15 on; measured on 1.17.1) reads one number past
    the end of its (m, n) Jacobian: qrfac recomputes a column's norm after
    heavy cancellation as ``enorm(m - j, &a[(j + 1) + lda * k])``, one row
    too many (the Fortran's ``m - j`` counted from 1).  For the last column
    that number lies outside the block (valgrind: an invalid read 0 bytes
    after the 8 m n byte block ``minpack_lmder`` allocates), in the 8 bytes
    malloc leaves past a block of 8 m n bytes when m n is even (always
    here: two residuals a measurement): whatever an earlier array left
    there.  It only reorders the column pivoting, but on an ill-conditioned
    fit (condition ~4e8) that changes the last bits of every step, and the
    fit ends elsewhere in its flat valley: the same track fitted twice in
    one process gave v0 differing by 1e-9 relative, its standard error by
    20% and t1 by 0.5 s (docs/measurements.md, determ).  An array of one
    number more, zeroed and released just before the call, puts zeros
    there: malloc hands the same block (last freed, same size class) to
    the Jacobian, and a zero adds nothing to the norm.  Not guaranteed by
    any allocator's contract; measured to remove the spread (same section).
    """
    np.zeros(m * n + 1)


def _lmder_answers() -> bool:
    """Whether scipy's private lmder takes the call :func:`lm_fit` makes and
    answers as least_squares does, on a two-parameter line (decided once, at
    import: a scipy that changed its arguments would raise TypeError at
    every fit, and one caught there would also catch the caller's own;
    review 10a, 10c)."""
    t = np.linspace(0.0, 1.0, 5)
    y = 0.5 + 2.0 * t + 0.01 * np.cos(7 * t)

    def resid(p):
        return p[0] + p[1] * t - y

    def jac(p):
        return np.c_[np.ones_like(t), t]

    try:
        mine = lm_fit(resid, [0.0, 0.0], jac)
    except (TypeError, KeyError, IndexError, AttributeError, ValueError):
        return False
    ref = least_squares(resid, [0.0, 0.0], jac=jac, x_scale="jac", method="lm")
    return bool(np.allclose(mine.x, ref.x, rtol=1e-12, atol=1e-12))


if _minpack is not None and not _lmder_answers():  # pragma: no cover - a scipy that moved them
    _minpack = None
