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


def off_path(uv: np.ndarray, ok: np.ndarray, radius_px: float, t: np.ndarray | None = None,
             tol_radii: float = PATH_TOL_RADII, max_gap: int = PATH_GAP_FRAMES) -> np.ndarray:
    """Frames (bool, shape (n,)) whose centre ``uv`` (px, shape (n, 2)) is off
    the path its ``ok`` neighbours trace.

    Each ok frame gets predictions from pairs of other ok frames, a constant
    velocity carried to its time ``t`` (s; frame numbers when None, so a
    variable frame rate is followed): from the two before it (carried
    forward), the two after it (carried back), the nearest before and after
    (interpolated); and the same from the pairs one step farther out,
    skipping its nearest neighbour on each side.  Each pair's frames lie
    within ``max_gap`` frames of each other and of it.  A prediction misses
    when it is farther than ``tol_radii`` radii ``radius_px`` plus half the
    pair's own travel over the interval it is carried (a velocity that
    changes by up to half within it: the frame whose exposure spans the
    strike, at any speed).  A frame is flagged when every prediction of the
    near kind misses, or every one of the far kind does (at least one
    made): a pair of false centres side by side vouches for each other
    through the near predictions, never through the far ones.  A true frame
    beside a false one keeps the predictions from its other side; a frame at
    the strike keeps the rest's (before) or the departure's (after).  Passes
    repeat without the frames flagged so far, until none is added.
    """
    ok = np.asarray(ok, bool)
    t = np.arange(len(ok), dtype=float) if t is None else np.asarray(t, float)
    out = np.zeros(len(ok), bool)
    for _ in range(PATH_PASSES):
        more = _off_path_once(uv, ok & ~out, t, radius_px, tol_radii, max_gap)
        if not more.any():
            break
        out |= more
    return out


def _misses(P, T, a: int, b: int, x: float, y: float, tk: float, tol: float) -> bool:
    """Whether the centre (x, y) at time tk lies off the line through ok
    frames a and b (indices into P, T), by more than tol plus half the
    pair's travel over the interval carried."""
    dt = T[b] - T[a]
    f = (tk - T[a]) / dt
    px, py = P[a][0] + f * (P[b][0] - P[a][0]), P[a][1] + f * (P[b][1] - P[a][1])
    if a < b and T[a] <= tk <= T[b]:
        carried = min(tk - T[a], T[b] - tk)
    else:
        carried = min(abs(tk - T[a]), abs(tk - T[b]))
    step = ((P[b][0] - P[a][0]) ** 2 + (P[b][1] - P[a][1]) ** 2) ** 0.5
    return ((x - px) ** 2 + (y - py) ** 2) ** 0.5 > tol + 0.5 * step * carried / dt


def _off_path_once(uv, ok, t, radius_px, tol_radii, max_gap) -> np.ndarray:
    """One pass of :func:`off_path`."""
    n = len(ok)
    out = np.zeros(n, bool)
    idx = np.flatnonzero(ok)
    m = len(idx)
    if m < 3:
        return out
    tol = tol_radii * radius_px
    P = np.asarray(uv, float)[idx].tolist()
    T = t[idx].tolist()
    K = idx.tolist()

    def near(i, j):  # ok frames i, j (indices into K) close enough to predict
        return 0 <= i < m and 0 <= j < m and abs(K[j] - K[i]) <= max_gap

    for j in range(m):
        x, y = P[j]
        tk = T[j]
        verdicts = {1: [], 2: []}
        for s in (1, 2):  # s = 1: the nearest neighbours; 2: one step farther out
            if near(j - s - 1, j - s) and near(j - s, j):
                verdicts[s].append(_misses(P, T, j - s - 1, j - s, x, y, tk, tol))
            if near(j + s, j + s + 1) and near(j, j + s):
                verdicts[s].append(_misses(P, T, j + s, j + s + 1, x, y, tk, tol))
            if near(j - s, j) and near(j, j + s):
                verdicts[s].append(_misses(P, T, j - s, j + s, x, y, tk, tol))
        if any(v and all(v) for v in verdicts.values()):
            out[K[j]] = True
    return out


__all__ = ["PATH_GAP_FRAMES", "PATH_TOL_RADII", "off_path"]
