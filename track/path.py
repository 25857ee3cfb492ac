"""Found centres checked against the ball's path through their neighbours (pure).

A ball's centre moves continuously: between consecutive frames by at most
its speed's worth, and along a line or a gentle curve over a few frames.  A
found centre that none of its neighbours can account for was something else
in the ball's window (the cue's tip at the strike, the dark rim's crescent of
a shaded ball close to the felt's colour): it is dropped, not reported.  A
frame left out is allowed; a wrong centre is not.
"""

from __future__ import annotations

import numpy as np

# A centre is off the path when it lies farther than this many radii from
# each prediction its neighbours make (the two ok frames before it carried
# forward, the two after it carried back, and the line between the nearest
# before and after).  Measured on the 60 realistic shots of issue 10 (seeds
# 5-9, MJPG and FFV1): false centres 1.2-4.4 radii off (the cue's tip at a
# 480-fps strike, sample_scenes(6, 7, realistic, MJPG)[4]; the red ball's
# dark rim, [5]) against true ones whose predictions miss by at most ~0.2
# radii (a sliding ball's deceleration over the gaps below; a cushion's
# reversal, larger, lasts one frame and misses only the predictions across it).
PATH_TOL_RADII = 0.5
# Neighbours farther than this many frames away predict nothing: over a
# longer gap the path's curvature (the deceleration, 2 m/s^2 while sliding)
# and a cushion make the prediction itself uncertain.
PATH_GAP_FRAMES = 4
# Passes of the check, each without the frames flagged before (a run of
# false frames is peeled from its ends); few are ever needed.
PATH_PASSES = 5


def off_path(uv: np.ndarray, ok: np.ndarray, radius_px: float, tol_radii: float = PATH_TOL_RADII,
             max_gap: int = PATH_GAP_FRAMES) -> np.ndarray:
    """Frames (bool, shape (n,)) whose centre ``uv`` (px, shape (n, 2)) is off
    the path its ``ok`` neighbours trace.

    Each ok frame gets up to three predictions: from the two nearest ok
    frames before it (a constant velocity carried forward), from the two
    after it (carried back), and from the nearest before and after
    (interpolated), each only where its frames lie within ``max_gap`` frames
    of each other and of it.  A frame all of whose predictions (at least
    one) miss it by more than ``tol_radii`` radii ``radius_px`` is flagged.
    A true frame beside a false one keeps the prediction from its other
    side; a frame at the strike keeps the rest's (before) or the departure's
    (after).  Passes repeat without the frames flagged so far, until none is
    added: a false frame's prediction through its false neighbour (two in a
    row beside a lost frame) could otherwise pass it.
    """
    ok = np.asarray(ok, bool)
    out = np.zeros(len(ok), bool)
    for _ in range(PATH_PASSES):
        more = _off_path_once(uv, ok & ~out, radius_px, tol_radii, max_gap)
        if not more.any():
            break
        out |= more
    return out


def _off_path_once(uv, ok, radius_px, tol_radii, max_gap) -> np.ndarray:
    """One pass of :func:`off_path`."""
    uv = np.asarray(uv, float)
    n = len(ok)
    out = np.zeros(n, bool)
    idx = np.flatnonzero(ok)
    if len(idx) < 3:
        return out
    tol = tol_radii * radius_px
    P = uv[idx]
    m = len(idx)
    for j in range(m):
        k = idx[j]
        preds = []
        if j >= 2 and k - idx[j - 1] <= max_gap and idx[j - 1] - idx[j - 2] <= max_gap:
            a, b = idx[j - 2], idx[j - 1]
            preds.append(P[j - 1] + (P[j - 1] - P[j - 2]) * (k - b) / (b - a))
        if j + 2 < m and idx[j + 1] - k <= max_gap and idx[j + 2] - idx[j + 1] <= max_gap:
            a, b = idx[j + 1], idx[j + 2]
            preds.append(P[j + 1] + (P[j + 1] - P[j + 2]) * (a - k) / (b - a))
        if 0 < j < m - 1 and k - idx[j - 1] <= max_gap and idx[j + 1] - k <= max_gap:
            a, b = idx[j - 1], idx[j + 1]
            preds.append(P[j - 1] + (P[j + 1] - P[j - 1]) * (k - a) / (b - a))
        if preds and all(np.hypot(*(P[j] - p)) > tol for p in preds):
            out[k] = True
    return out


__all__ = ["PATH_GAP_FRAMES", "PATH_TOL_RADII", "off_path"]
