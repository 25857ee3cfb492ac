"""Datasets: seeded scenes rendered to videos, with scene files and truth.

Each shot ``i`` is ``shot_NNNN.avi`` (``.mp4`` for H264), ``shot_NNNN.truth.csv`` and
``shot_NNNN.json``.  The scene file is written last, as the mark that the shot
is complete, so an interrupted run loses at most the shot in progress and a
rerun skips every shot already there.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from cuespin.data_gen.sampler import sample_scenes
from cuespin.physics.scene import scene_to_dict


def shot_stem(i: int) -> str:
    """File stem of shot ``i`` in a dataset folder."""
    return f"shot_{i:04d}"


def generate_dataset(out: Path, n: int, seed: int, preset: str | None = None,
                     codec: str | None = None, fps: float | None = None,
                     progress=None, look: str = "plain", camera: str = "topdown") -> dict:
    """Sample ``n`` scenes from ``seed`` and render each into ``out``.

    Parameters
    ----------
    out : Path
        Dataset folder (created if absent).
    n : int
        Number of shots.
    seed : int
        Dataset seed; the same seed gives the same scenes and videos.
    preset : str, optional
        One preset for every shot; a mix of all presets when None.
    codec : str, optional
        FourCC for every video (or H264, written to .mp4); the renderer's
        default (MJPG) when None.
    fps : float, optional
        Frame rate for every shot; sampled when None.
    progress : callable, optional
        ``progress(total, desc, unit)`` returning a context-manager bar.
    look : str
        ``plain`` or ``realistic`` (see :func:`cuespin.data_gen.sampler.sample_scene`).
    camera : str
        ``topdown`` or ``tilted`` (same).

    Returns
    -------
    dict
        ``{"written": int, "skipped": int, "paths": [video paths]}``.
    """
    from cuespin.render.draw import render_settings
    from cuespin.render.video import render_video, truth_path, video_suffix
    from cuespin.sceneio import write_scene

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    scenes = sample_scenes(n, seed, preset=preset, fps=fps, codec=codec, look=look,
                           camera=camera)
    written = skipped = 0
    paths = []
    bar = progress(n, "generate", "shot") if progress else None
    try:
        for i, scene in enumerate(scenes):
            stem = shot_stem(i)
            suffix = video_suffix(str(render_settings(scene)["codec"]))  # .mp4 for H264
            video, scene_file = out / f"{stem}{suffix}", out / f"{stem}.json"
            paths.append(video)
            if _complete(scene_file, video, scene):
                skipped += 1
            else:
                part = out / f"{stem}.part{suffix}"
                render_video(scene, part)
                os.replace(truth_path(part), truth_path(video))
                os.replace(part, video)
                write_scene(scene_file, scene)
                written += 1
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return {"written": written, "skipped": skipped, "paths": paths}


def _complete(scene_file: Path, video: Path, scene) -> bool:
    from cuespin.render.video import truth_path

    if not (scene_file.exists() and video.exists() and truth_path(video).exists()):
        return False
    try:
        return json.loads(scene_file.read_text()) == json.loads(json.dumps(scene_to_dict(scene)))
    except (OSError, json.JSONDecodeError):
        return False
