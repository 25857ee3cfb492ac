"""Tracks straight from the forward model with Gaussian noise: the project's
own generator for calibrating decisions and checking error bars by
simulation (no video: fast enough for thousands of tracks).

Pure: a seed (or a numpy Generator) in, arrays out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cuespin.data_gen.sampler import sample_shot
from cuespin.physics.motion import BallParams, Shot, phases
from cuespin.recover.mle import INTER_CODEC_ACF, model_track

# Frame rates and per-axis centre noise (m) the calibration spans: the
# sampler's frame rates, and the tracker's stated errors at 500 px/m from
# noise 0.1 to 10 grey levels (about 0.01-0.3 px, measured in
# benchmarks/track.py).
FPS_GRID = (60.0, 120.0, 240.0, 480.0)
SIGMA_GRID_M = (2e-5, 1e-4, 6e-4)
# Analysed tracks end at rest or after this long from the strike (s): the
# calibration's tracks, kept short so thousands run in minutes.
MAX_AFTER_STRIKE_S = 2.0


@dataclass(frozen=True)
class SimTrack:
    """One simulated track: times (s), centres (m), per-axis error (m), truth."""

    t: np.ndarray
    xy: np.ndarray
    sigma: float
    shot: Shot
    params: BallParams
    exposure_s: float
    fps: float


def simulate_track(shot: Shot, params: BallParams, fps: float, sigma: float, rng,
                   exposure_s: float = 0.0, t_end: float | None = None,
                   t_start: float = 0.0, rho: float = 0.0, acf=None) -> SimTrack:
    """The exposure-averaged centre at frame times ``k / fps`` plus N(0, sigma^2) per axis.

    ``t_end`` defaults to 0.3 s after rest, at most :data:`MAX_AFTER_STRIKE_S`
    after the strike.  ``rho``: the errors are AR(1) along the track with
    this lag-1 correlation (the same variance; a lossy codec at low noise,
    README), independent between axes; ``acf``: instead, correlated in time
    as an inter-frame codec's whole error (:func:`shared_errors`).
    """
    rng = np.random.default_rng(rng)
    ph = phases(shot, params)
    if t_end is None:
        t_end = min(ph.t2 + 0.3, shot.t0 + MAX_AFTER_STRIKE_S)
    t = np.arange(np.ceil(t_start * fps), np.floor(t_end * fps) + 1) / fps
    e = ar1_errors(len(t), rho, rng) if acf is None else shared_errors(len(t), fps, rng, acf)
    xy = model_track(shot, params, t, exposure_s) + sigma * e
    return SimTrack(t, xy, float(sigma), shot, params, float(exposure_s), float(fps))


def ar1_errors(n: int, rho: float, rng) -> np.ndarray:
    """(n, 2) errors of unit variance per axis, AR(1) along the rows with
    lag-1 correlation ``rho`` (``rho^k`` k rows apart; 0: independent),
    independent between axes: ``e_k = rho e_(k-1) + sqrt(1 - rho^2) w_k``,
    started stationary.  Draws ``(n, 2)`` normals from ``rng``."""
    e = rng.standard_normal((n, 2))
    if rho:
        from scipy.signal import lfilter
        e[1:] *= np.sqrt(1.0 - rho**2)
        e = lfilter([1.0], [1.0, -rho], e, axis=0)
    return e


def shared_errors(n: int, fps: float, rng, acf=INTER_CODEC_ACF) -> np.ndarray:
    """(n, 2) errors of unit variance per axis at frames ``1 / fps`` s apart,
    correlated in time as an inter-frame codec's whole error is
    (recover.mle.INTER_CODEC_ACF ``(a, b, tau, tau_long)``: ``a
    exp(-dt / tau_long) + b exp(-dt / tau)``): the sum of two AR(1)
    (:func:`ar1_errors`) and an independent part."""
    a, b, tau, tau_long = acf
    return (np.sqrt(a) * ar1_errors(n, np.exp(-1.0 / (tau_long * fps)), rng)
            + np.sqrt(b) * ar1_errors(n, np.exp(-1.0 / (tau * fps)), rng)
            + np.sqrt(1.0 - a - b) * rng.standard_normal((n, 2)))


def _grid_point(i: int, fps_grid, sigma_grid):
    """The ``i``-th generated track's frame rate and noise: frame rates
    cycle fastest, then noise levels."""
    return fps_grid[i % len(fps_grid)], sigma_grid[(i // len(fps_grid)) % len(sigma_grid)]


def _exposure(rng, fps: float, blur: bool) -> float:
    """Exposure (s): 0.3-1 frame half the time (as the sampler draws them)
    when ``blur``, else 0; draws from ``rng`` only when ``blur``."""
    return float(rng.uniform(0.3, 1.0) / fps) if blur and rng.random() < 0.5 else 0.0


def null_rolling_tracks(n: int, seed: int, fps_grid=FPS_GRID, sigma_grid=SIGMA_GRID_M,
                        blur: bool = True, rho: float = 0.0, acf=None):
    """``n`` tracks rolling from the strike (paper case 4: no slip to see),
    cycling over frame rates and noise levels, exposures 0.3-1 frame half
    the time (as the sampler draws them); ``rho``: AR(1) errors, ``acf``:
    an inter-frame codec's (:func:`simulate_track`).  Yields :class:`SimTrack`."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        fps, sigma = _grid_point(i, fps_grid, sigma_grid)
        shot, params = sample_shot(rng, "case4")
        exposure = _exposure(rng, fps, blur)
        yield simulate_track(shot, params, fps, sigma, rng, exposure, rho=rho, acf=acf)


def sliding_tracks(n: int, seed: int, presets=("random", "case1", "case3", "case5", "masse"),
                   fps_grid=FPS_GRID, sigma_grid=SIGMA_GRID_M, blur: bool = True, rho: float = 0.0,
                   seen_s: tuple[float, float] | None = None, acf=None):
    """``n`` tracks of shots that slide (the sampler's presets), cycling over
    frame rates and noise levels; ``rho``: AR(1) errors, ``acf``: an
    inter-frame codec's (:func:`simulate_track`); ``seen_s``: each clip ends a uniform
    ``seen_s[0]``-``seen_s[1]`` seconds after the strike, if sooner (as a
    realistic 1.5-s clip sees the ball).  Yields :class:`SimTrack`."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        fps, sigma = _grid_point(i, fps_grid, sigma_grid)
        shot, params = sample_shot(rng, presets[i % len(presets)])
        exposure = _exposure(rng, fps, blur)
        ph = phases(shot, params)
        t_end = min(ph.t2 + 0.3, max(ph.t1 + 1.0, shot.t0 + MAX_AFTER_STRIKE_S))
        if seen_s is not None:
            t_end = min(t_end, shot.t0 + rng.uniform(*seen_s))
        yield simulate_track(shot, params, fps, sigma, rng, exposure, t_end=t_end, rho=rho, acf=acf)


def mixed_tracks(n: int, seed: int):
    """``n`` tracks alternately rolling from the strike
    (:func:`null_rolling_tracks`) and sliding (:func:`sliding_tracks`): the
    null tracks of a question every track is asked (are the errors
    autocorrelated?)."""
    roll = null_rolling_tracks((n + 1) // 2, seed)
    slide = sliding_tracks(n // 2, seed + 1)
    for i in range(n):
        yield next(roll) if i % 2 == 0 else next(slide)


def case2_tracks(n: int, seed: int, fps_grid=FPS_GRID, sigma_grid=SIGMA_GRID_M, blur: bool = True,
                 rho: float = 0.0):
    """``n`` tracks of shots whose sliding runs into the rest (paper case 2:
    ``x1 = x2``), cycling over frame rates and noise levels, seen to rest;
    ``rho``: AR(1) errors (:func:`ar1_errors`).  Yields :class:`SimTrack`."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        fps, sigma = _grid_point(i, fps_grid, sigma_grid)
        shot, params = sample_shot(rng, "case2")
        exposure = _exposure(rng, fps, blur)
        yield simulate_track(shot, params, fps, sigma, rng, exposure, t_end=phases(shot, params).t2 + 0.3, rho=rho)


def rolls_to_rest_tracks(n: int, seed: int, presets=("case1", "case3", "case5"), rest_s=(0.6, 2.5),
                         fps_grid=FPS_GRID, sigma_grid=SIGMA_GRID_M, blur: bool = True, rho: float = 0.0):
    """``n`` tracks of straight shots that slide, then roll to a rest in
    view (the sampler's presets: paper cases 1, 3, 5; the line method's
    case with ``x1`` apart from ``x2``), each slowed (``v0`` and ``w0`` by
    one factor, so the case is kept) to come to rest a uniform
    ``rest_s[0]``-``rest_s[1]`` seconds after the strike when it would
    take longer (as a clip sees a slow shot to its rest: the presets'
    0.5-3 m/s roll for up to 19 s), seen to 0.3 s after the rest.  Cycles
    over frame rates and noise levels as the others; ``rho``: AR(1)
    errors (:func:`ar1_errors`).  Yields :class:`SimTrack`."""
    from dataclasses import replace
    rng = np.random.default_rng(seed)
    for i in range(n):
        fps, sigma = _grid_point(i, fps_grid, sigma_grid)
        shot, params = sample_shot(rng, presets[i % len(presets)])
        ph = phases(shot, params)
        f = min(1.0, float(rng.uniform(*rest_s)) / (ph.t2 - shot.t0))
        shot = replace(shot, v0=tuple(f * np.asarray(shot.v0)), w0=tuple(f * np.asarray(shot.w0)))
        exposure = _exposure(rng, fps, blur)
        yield simulate_track(shot, params, fps, sigma, rng, exposure, t_end=phases(shot, params).t2 + 0.3, rho=rho)


def short_slip_tracks(n: int, seed: int, frames=(0.2, 1.0), fps_grid=(60.0, 120.0, 240.0),
                      sigma_grid=SIGMA_GRID_M, blur: bool = True, to_rest: bool = False):
    """``n`` tracks of shots that slide for ``frames`` (a uniform range, in
    frames) after the strike: the sampler's rolling-from-the-strike shot
    (case 4) given a slip ``|u0| = 7/2 mu_s g tau1`` (eq. 10) in a random
    direction, v0 kept (as benchmarks/short_slide.py draws them).
    ``to_rest``: each track runs on to 0.3 s after the rest (seconds of
    rolling, where the sliding arc once ran on), not :data:`MAX_AFTER_STRIKE_S`.
    Yields :class:`SimTrack`."""
    from cuespin.physics.motion import z_cross
    rng = np.random.default_rng(seed)
    for i in range(n):
        fps, sigma = _grid_point(i, fps_grid, sigma_grid)
        shot, params = sample_shot(rng, "case4")
        tau1 = float(rng.uniform(*frames)) / fps
        ang = rng.uniform(0, 2 * np.pi)
        u0 = 3.5 * params.mu_s * params.g * tau1 * np.array([np.cos(ang), np.sin(ang)])
        v0 = np.asarray(shot.v0, float)
        s = Shot(x0=shot.x0, v0=v0, w0=z_cross(v0 - u0) / params.R, t0=shot.t0)
        exposure = _exposure(rng, fps, blur)
        yield simulate_track(s, params, fps, sigma, rng, exposure,
                             t_end=phases(s, params).t2 + 0.3 if to_rest else None)


def leaves_table_tracks(n: int, seed: int, fps_grid=FPS_GRID, sigma_grid=SIGMA_GRID_M, blur: bool = True,
                        preset: str = "leaves_table"):
    """``n`` tracks of the sampler's fast shots at a near cushion (preset
    ``leaves_table``: 2.5-5 m/s from near the middle, spin up to v0 / R in
    any direction, so sliding often outlasts the track), each ending when
    the ball's centre comes within a radius of the cushion (the frames the
    ball is seen before it leaves the table, about 0.1-0.3 s after the
    strike); ``preset`` ``case4`` gives the same tracks rolling from the
    strike (v0 kept).  Cycles over frame rates and noise levels as the
    others.  Yields :class:`SimTrack`."""
    from cuespin.physics.motion import positions, z_cross
    from cuespin.physics.scene import Table
    rng = np.random.default_rng(seed)
    width = Table().width
    for i in range(n):
        fps, sigma = _grid_point(i, fps_grid, sigma_grid)
        shot, params = sample_shot(rng, "leaves_table")
        if preset == "case4":  # rolling from the strike: w0 = z x v0 / R (eq. 8)
            shot = Shot(x0=shot.x0, v0=shot.v0, w0=z_cross(np.asarray(shot.v0, float)) / params.R, t0=shot.t0)
        exposure = _exposure(rng, fps, blur)
        # The time the centre reaches a radius from the cushion it heads for
        # (the shot is along y), on a 1 ms grid.
        t = shot.t0 + np.arange(0.0, MAX_AFTER_STRIKE_S, 1e-3)
        y = positions(shot, params, t)[:, 1]
        out = (y <= params.R) | (y >= width - params.R)
        t_end = float(t[np.argmax(out)]) if np.any(out) else None
        yield simulate_track(shot, params, fps, sigma, rng, exposure, t_end=t_end)
