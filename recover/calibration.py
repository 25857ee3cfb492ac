"""A calibration's error carried into v0 and w0.

A camera found from the table's corners is uncertain by as much as its
corners are (a corner clicked 1 px off put v0 10-30 stated errors off,
``docs/calibration.md``).  The tracker's errors know nothing of it, so the
recovery states it separately: the same track is converted to table metres
through each camera of the calibration's sensitivity set (the camera
re-solved with one corner coordinate moved by its stated error in turn, or,
for automatic corners, with the corners and k1 moved jointly along each of
the 9 directions of their jackknife covariance; ``cuespin calibrate`` writes
them) and refitted, keeping every decision the
fit through the calibrated camera made (sliding or rolling, sliding ended,
the segmentation's strike and rest, the paper's path shape and root:
recover.estimate.Decided), so the spread is the camera's alone and never a
model that a perturbed camera tips the other way; to first order, with the
moves' outer products summing to the corners' covariance (independent
coordinates, or the joint moves of a covariance), the calibration's variance
of an answer ``q`` is ``sum_k (q_k - q)^2``.

First order is enough at a click's 1 px: the chain from the corners through
the pose and the table metres to v0 and w0 is linear there (the +1 px moves
state what central +-1 px ones do to 0.05%, tests/test_calibration_error.py),
so a sigma-point or central share would state the same.  Keeping the
decisions matters: refits that re-decide (the fit's AR(1) error model, which
a camera's misfit alone can switch on) stated v0 z RMS 1.15 where these give
1.07 on the same 46 clicked draws.  What no share of this kind carries: a
camera error large enough to bend the track makes the fit take AR(1) errors,
so on those draws the error is larger than the share says (z RMS 1.2)
and on the rest smaller (0.8-0.9), about 1 overall (docs/measurements.md,
clicked13).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

# The answers whose calibration share is stated (each a 2-vector).
PROPAGATED = ("v0", "w0")


def calibration_variance(answer: dict, refits: Sequence[dict]) -> dict:
    """Per-component variance of one method's answers over the refits.

    Parameters
    ----------
    answer : dict
        The method's answer through the calibrated camera (``v0``, ``w0``:
        2-vectors in m/s and rad/s, or None).
    refits : sequence of dict
        The same method's answers through each perturbed camera.

    Returns
    -------
    dict
        ``{"v0": [var_x, var_y], "w0": [...]}`` ((m/s)^2, (rad/s)^2) for the
        answers the method gave and every refit gave too; a refit that did not
        give one (the perturbed camera left the fit without an answer) makes
        that answer's calibration error unknown (None).
    """
    out = {}
    for key in PROPAGATED:
        q = answer.get(key)
        if q is None:
            continue
        qk = [r.get(key) for r in refits]
        if not qk or any(v is None for v in qk):
            out[key] = None
            continue
        d = np.asarray(qk, dtype=float) - np.asarray(q, dtype=float)
        out[key] = np.sum(d**2, axis=0).tolist()
    return out


def add_calibration_error(methods: dict, refit: Callable[[object], dict], cameras: Sequence) -> None:
    """Add the calibration's share to each answering method's standard errors.

    Each method that gave ``v0`` (and ``w0``) gets ``stderr_calibration``
    (the calibration's own standard error per component) and its ``stderr``
    becomes the root sum of squares of the fit's and the calibration's (the
    paper method's too); ``stderr_fit`` keeps the fit's alone.  Changes
    ``methods`` in place.

    Parameters
    ----------
    methods : dict
        The recover result's ``methods`` (through the calibrated camera).
    refit : callable
        ``refit(camera) -> methods`` of the same track through another camera.
    cameras : sequence of Camera
        The calibration's perturbed cameras.
    """
    if not cameras:
        return
    refits = [refit(cam) for cam in cameras]
    for name, m in methods.items():
        var = calibration_variance(m, [r.get(name, {}) for r in refits])
        if not var:
            continue
        se = dict(m.get("stderr") or {})
        m["stderr_fit"] = {k: se.get(k) for k in PROPAGATED}
        m["stderr_calibration"] = {k: None if v is None else np.sqrt(v).tolist() for k, v in var.items()}
        for key, v in var.items():
            if se.get(key) is None or v is None:
                se[key] = None if v is None else se.get(key)
                continue
            se[key] = np.sqrt(np.square(se[key]) + np.asarray(v)).tolist()
        m["stderr"] = se


def track_posterior(shifts, residual_shifts, residuals) -> tuple[np.ndarray, np.ndarray]:
    """What the track itself says about the calibration (not used by the
    recovery yet: measured offline, docs/measurements.md, clicked13).

    Each perturbed camera is a one-standard-error move of one independent
    unit of the calibration's error (a corner coordinate, f's or the bow's
    share), so the moves' prior is N(0, I).  Refitted with the main fit's
    decisions, camera k moves the answer by ``shifts[k]`` and the fit's
    whitened residuals by ``residual_shifts[k]``; to first order the main
    fit's residuals are ``r = B eps + noise`` (unit, white) with ``eps`` the
    calibration's actual error in those units.  One Gauss-Newton step under
    the prior: ``eps = (B'B + I)^-1 B' r``, the answer's correction
    ``-J eps`` and the calibration's remaining variance ``diag(J (B'B +
    I)^-1 J')``.

    Parameters
    ----------
    shifts : array_like, shape (m, p)
        ``q_k - q`` of the p answers (any units) for the m cameras.
    residual_shifts : array_like, shape (m, n)
        The refits' whitened residuals minus the main fit's (flattened).
    residuals : array_like, shape (n,)
        The main fit's whitened residuals.

    Returns
    -------
    correction : ndarray, shape (p,)
        ``-J eps``, to add to the answer.
    variance : ndarray, shape (p,)
        The calibration's variance of each answer given the track (<= the
        prior's ``sum_k (q_k - q)^2``).
    """
    J = np.asarray(shifts, dtype=float).T
    B = np.asarray(residual_shifts, dtype=float).T
    P = np.linalg.inv(B.T @ B + np.eye(B.shape[1]))
    eps = P @ (B.T @ np.asarray(residuals, dtype=float))
    return -J @ eps, np.einsum("ij,jk,ik->i", J, P, J)
