"""The Python API: what the command line does, as functions.

Everything here is re-exported from :mod:`cuespin`::

    import cuespin
    scene = cuespin.read_scene("shot.json")
    result = cuespin.recover_video("shot.avi", scene)

Results are the objects the stages already return (``Scene``,
``TrackResult``, ``FrameTruth``, the recover dict of docs/output.md); the
heavy imports (OpenCV, matplotlib) happen on first use, so ``import
cuespin`` stays cheap.  A ``scene`` argument may be a :class:`Scene` or the
path of a scene file.

The functions are ``render_scene`` and ``recover_video``, not ``render`` and
``recover``: those names belong to the stage subpackages ``cuespin.render``
and ``cuespin.recover``, and importing a subpackage rebinds its name on the
package, so a function of the same name would be replaced by the module.
"""

from __future__ import annotations

from pathlib import Path

from cuespin.physics.motion import BallParams, Shot
from cuespin.physics.scene import Scene
from cuespin.sceneio import InputError, read_scene, write_scene

TRACK_COLUMNS = ("frame", "t", "u_px", "v_px", "x_m", "y_m", "ok", "status", "stderr_m")


def _scene(scene) -> Scene:
    return scene if isinstance(scene, Scene) else read_scene(scene)


def make_scene(shot: Shot, params: BallParams = BallParams(), fps: float = 240.0, px_per_m: float = 500.0,
               exposure_s: float = 0.0, render: dict | None = None) -> Scene:
    """A scene for a known shot, seen by the conventions' top-down camera.

    Parameters
    ----------
    shot : Shot
        ``x0`` (m), ``v0`` (m/s), ``w0`` (rad/s), ``t0`` (s).
    params : BallParams
        Ball radius and friction.
    fps : float
        Frame rate (frames/s).
    px_per_m : float
        Resolution (px per m); 500 gives a 1280 x 640 view of the table.
    exposure_s : float
        Exposure (s); 0 for sharp frames.
    render : dict, optional
        Renderer settings (``noise_sigma``, ``codec``, ``max_duration``, ``seed``, ...).

    Returns
    -------
    Scene
    """
    from cuespin.data_gen.sampler import make_scene as _make

    return _make(shot, params, fps=fps, px_per_m=px_per_m, exposure_s=exposure_s, render=render)


def render_scene(scene, video, progress=None):
    """Render a scene with a truth block to a video and its ``.truth.csv``.

    Parameters
    ----------
    scene : Scene or path
        Must have ``truth`` (the shot to draw).
    video : str or Path
        Video to write (``.avi``; the codec is ``scene.render["codec"]``,
        MJPG by default, FFV1 lossless).
    progress : callable, optional
        ``progress(n)`` after each ``n`` frames.

    Returns
    -------
    FrameTruth
        Per-frame true centroid (px) and centre (m), also written to
        ``<video stem>.truth.csv``.
    """
    from cuespin.render.video import render_video

    scene = _scene(scene)
    if scene.truth is None:
        raise InputError("the scene has no truth block: render needs the shot to draw")
    return render_video(scene, Path(video), progress=progress)


def generate(out, n: int, seed: int = 0, preset: str | None = None, codec: str | None = None,
             fps: float | None = None) -> dict:
    """Write a seeded dataset: ``out/shot_NNNN.{avi,json,truth.csv}``.

    Parameters
    ----------
    out : str or Path
        Folder (created if absent).
    n : int
        Number of shots.
    seed : int
        Dataset seed: the same seed gives the same files; a rerun skips
        finished shots.
    preset : str, optional
        One kind of shot for all (``cuespin.data_gen.PRESETS``); a mix when None.
    codec : str, optional
        FourCC (MJPG lossy by default, FFV1 lossless).
    fps : float, optional
        Frame rate (frames/s); sampled from 60-480 when None.

    Returns
    -------
    dict
        ``{"written": int, "skipped": int, "paths": [video paths]}``.
    """
    from cuespin.data_gen.dataset import generate_dataset

    return generate_dataset(Path(out), n=n, seed=seed, preset=preset, codec=codec, fps=fps)


def track_video(video, scene, refine: str = "fit", progress=None):
    """Track the ball through a video: a sub-pixel centre per frame.

    Parameters
    ----------
    video : str or Path
        Any video OpenCV reads.
    scene : Scene or path
        Only ``physics`` and ``camera`` are used.
    refine : {"fit", "moments"}
        Exact disc-model fit (at the Cramer-Rao bound) or grey-weighted moments.
    progress : callable, optional
        ``progress(n)`` after each ``n`` frames.

    Returns
    -------
    TrackResult
        ``t`` (s), ``uv`` (px), ``xy`` (m), ``ok``, ``status``, ``stderr_px``
        (px per axis); see :func:`track_dataframe` for a table of it.

    Raises
    ------
    TrackError
        The video cannot be read at all.
    """
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import track_video as _track

    return _track(video, _scene(scene), TrackerConfig(refine=refine), progress=progress)


def track_dataframe(track, scene=None):
    """A track as a pandas DataFrame, one row per frame.

    Parameters
    ----------
    track : TrackResult
        What :func:`track_video` returns.
    scene : Scene or path, optional
        Its scene: the camera carries each frame's pixel error to the table.
        Without it the track's own camera is used; ``stderr_m`` is NaN when
        neither is at hand.

    Returns
    -------
    pandas.DataFrame
        Columns ``frame`` (index from 0), ``t`` (s), ``u_px``, ``v_px``
        (centre of the ball's image, px), ``x_m``, ``y_m`` (centre on the
        table, m), ``ok`` (bool: ball found), ``status`` (the tracker's word
        for the frame: ``ok``, ``no ball``, ...), ``stderr_m`` (the
        tracker's stated standard error of the centre per axis, m, the RMS
        of the two axes).  Coordinates are NaN where ``ok`` is False.
    """
    import numpy as np
    import pandas as pd

    from cuespin.pipeline.run import track_stderr_m
    from cuespin.track.tracker import STATUS_TEXT

    n = len(track.t)
    camera = _scene(scene).camera if scene is not None else getattr(track, "camera", None)
    if camera is not None:
        se = track_stderr_m(track, camera)
        stderr_m = np.sqrt(np.mean(se**2, axis=1))
    else:
        stderr_m = np.full(n, np.nan)
    uv, xy = np.asarray(track.uv, float).reshape(-1, 2), np.asarray(track.xy, float).reshape(-1, 2)
    return pd.DataFrame({
        "frame": np.arange(n), "t": np.asarray(track.t, float),
        "u_px": uv[:, 0], "v_px": uv[:, 1], "x_m": xy[:, 0], "y_m": xy[:, 1],
        "ok": np.asarray(track.ok, bool),
        "status": [STATUS_TEXT.get(int(s), str(int(s))) for s in np.asarray(track.status)],
        "stderr_m": stderr_m}, columns=list(TRACK_COLUMNS))


def recover_video(video, scene, method: str = "all", fit_friction: bool = False, refine: str = "fit",
            return_track: bool = False):
    """Track a video and recover the strike, v0 and w0 by both methods.

    Parameters
    ----------
    video : str or Path
        The video.
    scene : Scene or path
        Its scene (``physics`` and ``camera``).
    method : {"all", "paper", "mle"}
        The paper's closed form, the maximum-likelihood fit, or both.
    fit_friction : bool
        Estimate mu_s and mu_r too (maximum likelihood only).
    refine : {"fit", "moments"}
        Tracker refinement.
    return_track : bool
        Also return the :class:`TrackResult`.

    Returns
    -------
    dict or (dict, TrackResult)
        The JSON object ``cuespin recover --json`` prints: ``video``,
        ``track``, ``methods`` (``paper``, ``mle``: ``status``, ``reason``,
        ``x0`` m, ``t0`` s, ``v0`` m/s, ``w0`` rad/s, ``t1``, ``x1``,
        ``t2``, ``x2``, ``predicted``, ...), ``best``, ``timing_s``.  Every
        field is described in docs/output.md.
    """
    from cuespin.pipeline.run import run_recover

    return run_recover(video, _scene(scene), method, fit_friction, refine, return_track=return_track)


def show(video, scene, png=None, result=None, video_out=None, track=None):
    """Draw one shot: the track over a frame, each method's fitted path, residuals.

    Parameters
    ----------
    video : str or Path
        The video.
    scene : Scene or path
        Its scene.
    png : str or Path, optional
        Picture to write (PNG).
    result : dict, optional
        A recover result for this video; recovered here when None.
    video_out : str or Path, optional
        Also write the video with the fit drawn over it (``.mp4``).
    track : TrackResult, optional
        The video's track, if already at hand.

    Returns
    -------
    dict
        The recover result drawn.
    """
    from cuespin.pipeline.show import show_shot

    return show_shot(video, _scene(scene), png=png, result=result, video_out=video_out, track=track)


__all__ = ["BallParams", "InputError", "Scene", "Shot", "generate", "make_scene", "read_scene", "recover_video",
           "render_scene", "show", "track_dataframe", "track_video", "write_scene"]
