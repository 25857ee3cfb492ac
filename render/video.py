"""Writing a scene's frames to a real video file and its ``.truth.csv`` sidecar.

Frames are drawn on a second thread while the main thread encodes: numpy and
OpenCV release the GIL in their heavy loops, so on two cores drawing and
noise hide behind the encoder.
"""

from __future__ import annotations

import csv
import queue
import threading
from pathlib import Path

import cv2
import numpy as np

from cuespin.physics.scene import Scene
from cuespin.render.draw import FrameRenderer, FrameTruth, render_settings
from cuespin.videoio import quiet_native_stderr

LOSSLESS_CODECS = ("FFV1",)
LOSSY_CODECS = ("MJPG", "mp4v", "XVID")
_QUEUE_DEPTH = 8


class VideoError(RuntimeError):
    """The video could not be written (codec, path or OpenCV failure)."""


def open_writer(path: Path, codec: str, fps: float, size: tuple[int, int]) -> cv2.VideoWriter:
    """An OpenCV VideoWriter for 8-bit grey frames; raises VideoError if it won't open."""
    if len(codec) != 4:
        raise VideoError(f"codec must be a four-character code such as MJPG or FFV1, got {codec!r}")
    with quiet_native_stderr():
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), float(fps), size,
                                 isColor=False)
    if not writer.isOpened():
        raise VideoError(f"OpenCV cannot write codec {codec} to {path}; "
                         f"try MJPG (lossy) or FFV1 (lossless) in a .avi file")
    return writer


def truth_path(video: Path) -> Path:
    """``<video without extension>.truth.csv`` (CONVENTIONS.md)."""
    video = Path(video)
    return video.with_name(video.stem + ".truth.csv")


def write_truth_csv(path: Path, truth: FrameTruth) -> None:
    """Write the sidecar: ``frame,t,u_px,v_px,x_m,y_m`` per frame."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "t", "u_px", "v_px", "x_m", "y_m"])
        for k in range(len(truth.t)):
            w.writerow([k, repr(float(truth.t[k])), repr(float(truth.uv[k, 0])),
                        repr(float(truth.uv[k, 1])), repr(float(truth.xy[k, 0])),
                        repr(float(truth.xy[k, 1]))])


def encode_frames(frames, path: Path, codec: str, fps: float, size: tuple[int, int],
                  progress=None) -> int:
    """Encode an iterable of 8-bit grey frames, drawing them on a second thread.

    Parameters
    ----------
    frames : iterable of ndarray
        Frames, shape (height, width), uint8; consumed on a worker thread.
    path : Path
        Output video file.
    codec : str
        FourCC.
    fps : float
        Frame rate (frames per second).
    size : (int, int)
        ``(width, height)`` in pixels.
    progress : callable, optional
        Called with 1 after each frame is written.

    Returns
    -------
    int
        Frames written.
    """
    writer = open_writer(path, codec, fps, size)
    q: queue.Queue = queue.Queue(maxsize=_QUEUE_DEPTH)
    done = object()
    failure: list[BaseException] = []

    def produce():
        try:
            for fr in frames:
                q.put(fr)
        except BaseException as exc:  # surfaced on the main thread below
            failure.append(exc)
        finally:
            q.put(done)

    worker = threading.Thread(target=produce, daemon=True)
    worker.start()
    n = 0
    try:
        while (fr := q.get()) is not done:
            writer.write(fr)
            n += 1
            if progress is not None:
                progress(1)
    finally:
        writer.release()
        worker.join()
    if failure:
        raise failure[0]
    return n


def render_video(scene: Scene, path, progress=None, n_frames: int | None = None) -> FrameTruth:
    """Render a scene to a video file and write its ``.truth.csv`` beside it.

    Parameters
    ----------
    scene : Scene
        A scene with truth.
    path : str or Path
        Output video; its codec is ``render.codec`` (default MJPG).
    progress : callable, optional
        Called with 1 per frame written (e.g. a tqdm bar's ``update``).
    n_frames : int, optional
        Override the scene's video length.

    Returns
    -------
    FrameTruth
        The per-frame truth that was written to the sidecar.
    """
    path = Path(path)
    renderer = FrameRenderer(scene, n_frames)
    codec = str(render_settings(scene)["codec"])
    cam = scene.camera
    if codec not in LOSSLESS_CODECS and (cam.width % 2 or cam.height % 2):
        raise VideoError(f"codec {codec} needs an even frame size, got {cam.width}x{cam.height}; "
                         f"make camera.width and camera.height even or use FFV1")
    n = encode_frames(renderer.frames(), path, codec, cam.fps, (cam.width, cam.height), progress)
    if n != renderer.n_frames:
        raise VideoError(f"wrote {n} of {renderer.n_frames} frames to {path}")
    write_truth_csv(truth_path(path), renderer.truth)
    return renderer.truth


def read_truth_csv(path) -> dict[str, np.ndarray]:
    """Read a ``.truth.csv`` sidecar into arrays keyed by column name."""
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {name: np.atleast_1d(data[name]) for name in data.dtype.names}
