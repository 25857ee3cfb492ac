"""When each frame of a rendered video is taken: the one source of frame times.

The drawing loop (``render.draw``) draws frame ``k`` at ``t[k]`` and the
writer (``render.video``) stamps it with ``pts[k]`` in ``time_base``; both
take them from :func:`frame_times`, so the picture, the file's timestamps
and the truth sidecar cannot disagree.

Constant rate (the default): ``t_k = k / fps`` (CONVENTIONS.md), ``pts_k = k``
in a time base of ``1 / fps``.  Variable rate (``render.vfr_jitter = j > 0``,
as a phone writes when its exposure or load changes): each interval is
``(1 + j e_k) / fps`` with ``e_k`` uniform on [-1, 1], rounded to a
1/90000 s time base (MPEG's clock); ``t_k`` is then exactly what the file
stores, ``pts_k * time_base``, relative to frame 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

# MPEG's 90 kHz clock: the time base phones and MP4 muxers use for video.
# At 480 fps an interval is 187.5 ticks, so a jitter of 1% (1.9 ticks) is
# still resolved.
VFR_TIME_BASE = Fraction(1, 90000)
# Intervals may vary by at most this fraction either way: beyond it frames
# could come out of order or two at once.
MAX_VFR_JITTER = 0.5

VIDEO_DEFAULTS = {
    "vfr_jitter": 0.0,  # fraction by which frame intervals vary (0: constant rate)
}


@dataclass(frozen=True)
class FrameTimes:
    """Frame times of a video, as drawn and as stored in the file.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time of each frame (s), frame 0 at 0: ``pts * time_base`` relative
        to frame 0.
    pts : ndarray of int64, shape (n,)
        Presentation timestamps in ``time_base`` units.
    time_base : Fraction
        Seconds per ``pts`` tick.
    variable : bool
        True when the intervals were jittered (variable frame rate).
    """

    t: np.ndarray
    pts: np.ndarray
    time_base: Fraction
    variable: bool


def vfr_jitter(scene) -> float:
    """The scene's ``render.vfr_jitter`` (0 when absent), checked.

    Raises
    ------
    ValueError
        One line naming the key when it is not a number in [0, 0.5).
    """
    j = scene.render.get("vfr_jitter", VIDEO_DEFAULTS["vfr_jitter"])
    if isinstance(j, bool) or not isinstance(j, (int, float)) or not (0 <= j < MAX_VFR_JITTER):
        raise ValueError(f"render.vfr_jitter: expected a number in [0, {MAX_VFR_JITTER}), got {j!r}")
    return float(j)


def constant_time_base(fps: float) -> Fraction:
    """``1 / fps`` as an exact fraction (29.97 gives 100/2997)."""
    return 1 / Fraction(fps).limit_denominator(1_000_000)


def frame_times(scene, n_frames: int) -> FrameTimes:
    """The times of frames ``0 .. n_frames - 1`` of a scene's video.

    Parameters
    ----------
    scene : Scene
        Uses ``camera.fps`` and ``render.vfr_jitter`` / ``render.seed``.
    n_frames : int
        Number of frames.

    Returns
    -------
    FrameTimes
        ``t`` is ``k / fps`` at constant rate; with jitter, the jittered
        times rounded to :data:`VFR_TIME_BASE`, from a generator of their own
        seeded by ``render.seed`` (the noise's draws are left unchanged).
    """
    fps = float(scene.camera.fps)
    jitter = vfr_jitter(scene)
    k = np.arange(n_frames)
    if jitter == 0:
        return FrameTimes(t=k / fps, pts=k.astype(np.int64), time_base=constant_time_base(fps),
                          variable=False)
    seed = int(scene.render.get("seed", 0))
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5F3]))
    dt = (1.0 + jitter * rng.uniform(-1.0, 1.0, max(n_frames - 1, 0))) / fps
    tb = VFR_TIME_BASE
    ticks = np.rint(np.concatenate([[0.0], np.cumsum(dt)]) / float(tb)).astype(np.int64)
    if np.any(np.diff(ticks) <= 0):  # only above 45 kHz: no camera films that fast
        raise ValueError(f"camera.fps: {fps} is too fast for a 1/{tb.denominator} s time base")
    return FrameTimes(t=ticks * tb.numerator / tb.denominator, pts=ticks, time_base=tb,
                      variable=True)
