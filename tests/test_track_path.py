"""Found centres checked against the ball's path (track.path), and the
colour channel blind to white (track.colour.white_free): pure functions."""

import numpy as np

from cuespin.track.colour import WHITE_FREE_MIN, white_free
from cuespin.track.path import PATH_TOL_RADII, off_path

R_PX = 8.0


def path_with_noise(seed=0, n=120, noise=0.05 * R_PX):
    """A ball at rest for 40 frames, struck (3 px/frame, slowing), then
    reversed by a cushion at frame 100; per-frame noise ``noise`` px."""
    rng = np.random.default_rng(seed)
    k = np.arange(n, dtype=float)
    s = np.where(k < 40, 0.0, 3.0 * (k - 40) - 0.01 * (k - 40) ** 2)
    s = np.where(k > 100, 2 * s[100] - s, s)  # the cushion sends it back
    uv = np.c_[100 + 0.8 * s, 200 + 0.6 * s] + rng.normal(0, noise, (n, 2))
    return uv, np.ones(n, bool)


def test_true_path_is_kept_across_the_strike_and_a_cushion():
    uv, ok = path_with_noise()
    assert not off_path(uv, ok, R_PX).any()


def test_isolated_and_paired_jumps_are_caught_and_their_neighbours_kept():
    uv, ok = path_with_noise(1)
    bad = [20, 55, 56, 80]
    uv[20] += [2.5 * R_PX, -1.0 * R_PX]       # the cue's tip while the ball rests
    uv[55:57] += [[-1.3 * R_PX, 0], [-1.2 * R_PX, 0.3 * R_PX]]  # a crescent twice
    uv[80] += [0, 1.3 * R_PX]
    ok[[30, 57]] = False                       # frames lost around them
    flagged = off_path(uv, ok, R_PX)
    assert set(np.flatnonzero(flagged)) == set(bad)


def test_a_false_pair_at_the_start_does_not_vouch_for_itself():
    # Review of fp4: the red ball's crescent in the first two ok frames
    # (1.37 and 1.32 radii off, the same way) passed, each through the other.
    uv, ok = path_with_noise(3)
    ok[:11] = False
    uv[11:13] += [[1.37 * R_PX, 0.2], [1.32 * R_PX, 0.0]]
    assert set(np.flatnonzero(off_path(uv, ok, R_PX))) == {11, 12}


def test_fast_strike_and_variable_frame_times_keep_true_centres():
    # 60 fps, a frame-long exposure, struck at 4.7 radii a frame (8 m/s): the
    # frame whose exposure spans the strike lies between the rest and the
    # departure; frame intervals jittered by up to 40% (vfr_jitter), each
    # centre at its own time.
    rng = np.random.default_rng(4)
    n = 80
    t = np.cumsum(rng.uniform(0.6, 1.4, n))
    t0 = t[30] - 0.5                      # the strike inside frame 30's exposure
    v = 4.7 * R_PX
    # the exposure-averaged centre over [t - 1, t]: the mean of max(0, s - t0)
    lo, hi = np.maximum(t - 1 - t0, 0), np.maximum(t - t0, 0)
    s = v * (hi**2 - lo**2) / 2
    uv = np.c_[100 + 0.8 * s, 200 + 0.6 * s] + rng.normal(0, 0.05 * R_PX, (n, 2))
    assert not off_path(uv, np.ones(n, bool), R_PX, t=t).any()


def test_a_centre_within_the_tolerance_is_kept():
    uv, ok = path_with_noise(2, noise=0.0)
    uv[60] += [0.8 * PATH_TOL_RADII * R_PX, 0]
    assert not off_path(uv, ok, R_PX).any()


def test_white_free_weights_see_no_white_and_keep_the_hue():
    S = 7.8**2 * np.eye(3)
    d = np.array([-11.0, 76.0, 66.0])          # orange ball less red felt (BGR)
    w = white_free(d, S)
    assert w is not None and abs(w.sum()) < 1e-9 * np.abs(w).sum()
    kept = (w @ d) ** 2 / (w @ S @ w) / (d @ np.linalg.solve(S, d))
    assert WHITE_FREE_MIN <= kept < 1
    # A white ball on grey felt differs in brightness only: no such channel.
    assert white_free(np.array([120.0, 118.0, 121.0]), S) is None
