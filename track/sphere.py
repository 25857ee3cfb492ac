"""The lit sphere's geometry learnt from a video's frames (pure functions).

:class:`cuespin.track.model.SphereLook` is the ball's look with its light
direction, shininess and lens blur (the PSF) fixed for the video, each
frame fitting only its centre, blur and three linear coefficients.  Those
four numbers are learnt
here, once, from the frames the tracker first fits (before the strike the
ball rests: the same window many times, whose mean has the noise of one
frame divided by their number), by minimising the fits' residual sum over
them.  The tracker never reads the scene's ``render`` block: everything
comes from the pixels.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from cuespin.track.model import SphereLook, block_area, blur_nodes, fit_disc

# Frames whose centres lie within this of their group's first (px) are the
# same still ball (its blur, predicted from a velocity that is noise, too
# short to be modelled), averaged into one window before the fit: a resting ball's
# fitted centre scatters by its error (0.002-0.03 px), a moving one moves by
# its speed (>= 0.1 px a frame once it has left the rest).
STILL_PX = 0.05
# At most this many groups (the largest) enter the objective: each costs one
# fit per evaluation.
MAX_GROUPS = 3
# The search's start: the elevation and shininess the renderer's and real
# lights span (50-80 deg, Blinn exponents 20-80), and the azimuth from the
# quadratic look's lit side or its opposite (the combination of channels
# may make the ball's diffuse term negative).
START_ELEVATIONS = (0.9, 1.15, 1.4)
START_SHININESS = (15.0, 40.0, 100.0)
# ... and the PSF's variance (px^2): none, and the middle of data_gen's
# lenses (sigma 0.5-1.0 px, variance 0.25-1.0).  From no blur alone, a small
# blurred matte ball's best start lay on the side away from the light (its
# broad Blinn lobe standing in for the blurred rim) and the search stayed
# there: benchmarks/track.py realistic seed 7 shot 4 (white on blue, r 7.6
# px, PSF 0.75, light at 3.67 rad in the image) learnt azimuth 0.53,
# shininess at its floor, every centre 0.16 px towards the light (err/se
# 6.3); the starts at 0.5 px^2 score 7417 against 17384 (found13).
START_PSF_VARS = (0.0, 0.5)
# Compass search: first steps (azimuth rad, elevation rad, log shininess,
# the PSF's variance px^2), halved when no move helps, until below this
# fraction of them.  The lens's blur is searched as its variance, from 0:
# it acts on the image at second order in sigma, so a search in sigma
# would start where nothing changes.
STEPS = (0.3, 0.12, 0.5, 0.25)
MIN_STEP_FRACTION = 1 / 64
ELEVATION_RANGE = (0.05, np.pi / 2)
# Below ~10 Blinn's lobe is as broad as the diffuse term and takes its
# place: on a matte ball (benchmarks/track.py realistic shot 1, seed 0, light
# at 1.38 rad) the search went to shininess 4.4 and elevation 1.48.
SHININESS_RANGE = (10.0, 2000.0)
# The PSF's variance (px^2): data_gen's lenses span sigma 0.5-1.0 px
# (data_gen/sampler.py); up to 2 px, a lens out of focus.
PSF_VAR_RANGE = (0.0, 4.0)


class Sample(NamedTuple):
    """One frame's converged fit, as the tracker had it: the window (grey
    levels, the tracker's combination), its felt, the corner ``u0, v0``
    (px), the centre ``c`` and blur ``b`` (px), the level ``G``, whether the
    blur was fitted, the quadratic look's coefficients (its lit side gives
    the light's azimuth) and the valid pixels (None: all)."""
    patch: np.ndarray
    felt: np.ndarray
    u0: int
    v0: int
    c: np.ndarray
    b: np.ndarray
    G: float
    fit_blur: bool
    shade: np.ndarray
    valid: np.ndarray | None


def still_members(samples: list) -> list:
    """The samples' indices grouped by the same still ball in the same
    window (:data:`STILL_PX`), largest group first, every group: list of
    lists of int."""
    groups: list[list] = []
    for i, s in enumerate(samples):
        for g in groups:
            f = samples[g[0]]
            if (f.u0, f.v0, f.patch.shape) == (s.u0, s.v0, s.patch.shape) and np.hypot(*(s.c - f.c)) <= STILL_PX \
                    and not s.fit_blur and not f.fit_blur and len(blur_nodes(np.hypot(*s.b))) == 1 \
                    and len(blur_nodes(np.hypot(*f.b))) == 1:
                g.append(i)
                break
        else:
            groups.append([i])
    groups.sort(key=len, reverse=True)
    return groups


def mean_sample(group: list) -> Sample:
    """One still ball's samples (a group of :func:`still_members`) as one:
    the windows and felts averaged, the pixels valid in all of them."""
    valid = None
    if any(s.valid is not None for s in group):
        valid = np.logical_and.reduce([np.ones(s.patch.shape, bool) if s.valid is None else s.valid for s in group])
    return group[0]._replace(patch=np.mean([s.patch for s in group], axis=0),
                             felt=np.mean([s.felt for s in group], axis=0), valid=valid)


def still_groups(samples: list) -> list:
    """The samples averaged into groups of the same still ball in the same
    window, largest first (at most ``MAX_GROUPS``): list of Sample."""
    return [mean_sample([samples[i] for i in g]) for g in still_members(samples)[:MAX_GROUPS]]


def _rss(groups, r: float, outline, look: SphereLook, block=1) -> float:
    """Residual sum of squares of the sphere's fits to the groups (inf when
    one fails), on the ``block`` x ``block`` means the tracker fits (a 4:2:0
    video seen through a luma-blind channel, :func:`fit_disc`'s ``block``):
    learnt on the pixels, the look absorbed the repeated chroma's steps
    (review7: lossless yuv420p shots 7 and 12, RMSE 0.094 / 0.129 ->
    0.047 / 0.054 px with the blocks)."""
    tot = 0.0
    for s in groups:
        f = fit_disc(s.patch, s.felt, s.u0, s.v0, s.c, r, s.G, b0=s.b, fit_blur=s.fit_blur, shade=look,
                     valid=s.valid, outline=outline, block=block, jackknife=False)  # its residual only
        if not f:
            return np.inf
        n = (s.patch.size if s.valid is None else int(s.valid.sum())) // block_area(block)
        tot += f.rms**2 * (n - 6 - (2 if s.fit_blur else 0))
    return tot


def _look(x) -> SphereLook:
    el = float(np.clip(x[1], *ELEVATION_RANGE))
    p = float(np.clip(np.exp(x[2]), *SHININESS_RANGE))
    return SphereLook(float(np.mod(x[0], 2 * np.pi)), el, p, float(np.sqrt(np.clip(x[3], *PSF_VAR_RANGE))))


def learn_sphere(samples: list, r: float, outline=None, start: SphereLook | None = None, block=1
                 ) -> tuple[SphereLook | None, float]:
    """The light's direction, the shininess and the lens's blur that
    explain the frames best.

    Parameters
    ----------
    samples : list of Sample
        The frames' converged fits (the quadratic look's).
    r : float
        Ball radius (px).
    outline : Ellipse, optional
        The ball's outline (None: the disc of radius ``r``).
    start : SphereLook, optional
        The search's only start (a look learnt before, against another
        felt); None: the grid of starts above.
    block : int
        The tracker's fitting grid: 2 on a 4:2:0 video seen through a
        luma-blind channel (its fits are on the 2 x 2 block means), else 1.

    Returns
    -------
    look : SphereLook or None
        None when no start could be fitted.
    rss : float
        Its residual sum of squares over the groups (levels^2).
    """
    groups = still_groups(samples)
    if not groups:
        return None, np.inf
    gu, gv = np.mean([s.shade[:2] for s in groups], axis=0)
    az0 = float(np.arctan2(gv, gu))
    best, best_x = np.inf, None
    if start is not None:
        starts = [np.array([start.azimuth, start.elevation, np.log(start.shininess), start.psf**2])]
    else:
        starts = [np.array([az, el, np.log(p), var]) for az in (az0, az0 + np.pi) for el in START_ELEVATIONS
                  for p in START_SHININESS for var in START_PSF_VARS]
    for x in starts:
        v = _rss(groups, r, outline, _look(x), block)
        if v < best:
            best, best_x = v, x
    if best_x is None:
        return None, np.inf
    step = np.array(STEPS, float)
    x = best_x
    while np.all(step >= np.array(STEPS) * MIN_STEP_FRACTION):
        moved = False
        for k in range(len(STEPS)):
            for sign in (1.0, -1.0):
                y = x.copy()
                y[k] += sign * step[k]
                v = _rss(groups, r, outline, _look(y), block)
                if v < best:
                    best, x, moved = v, y, True
                    break
        if not moved:
            step = step / 2
    return _look(x), best


def relearn_both_sides(samples: list, r: float, start: SphereLook, outline=None, block=1
                       ) -> tuple[SphereLook | None, float]:
    """The light learnt again against another felt from a look learnt
    before, searched from that look and from its mirror (azimuth + pi), the
    lower converged objective kept.

    The rule (s19, realistic seed 8 shot 19: a red ball 8 levels above red
    felt, PSF 0.96 px): against the first felt, which holds the resting
    ball's imprint, the two sides' converged objectives tie within 1% (8827
    right, 8740 wrong) and the first learning may end on the wrong side
    (azimuth 2.71 for the render's 5.81); against the better felt they part
    (5129 against 8176), but a search from one side's look never crosses to
    the other.  Searched from both: seed 8 shot 19 FFV1 RMSE 0.116 ->
    0.046 px, err/se 3.47 -> 1.66; seed 7 shots 4 and 14 (found13's) kept
    at 0.0111 px / 1.43 and 0.0155 px / 1.13.

    Parameters
    ----------
    samples : list of Sample
        The frames' converged fits, their felt the better one.
    r : float
        Ball radius (px).
    start : SphereLook
        The look learnt before (against the first felt).
    outline : Ellipse, optional
        The ball's outline (None: the disc of radius ``r``).
    block : int
        The tracker's fitting grid (:func:`learn_sphere`).

    Returns
    -------
    look : SphereLook or None
        The side with the lower objective; None when neither could be fitted.
    rss : float
        Its residual sum of squares over the groups (levels^2).
    """
    mirror = replace(start, azimuth=float(np.mod(start.azimuth + np.pi, 2 * np.pi)))
    return min((learn_sphere(samples, r, outline, start=s, block=block) for s in (start, mirror)),
               key=lambda got: got[1])

