"""Writing a scene's frames to a real video file and its ``.truth.csv`` sidecar.

AVI codecs (MJPG, FFV1, ...) are written by OpenCV; H.264 in MP4 by PyAV's
libx264, with each frame's presentation timestamp from
:func:`cuespin.render.timing.frame_times` (so a variable frame rate is
stored exactly and the sidecar's ``t`` is what the file says).

Frames are drawn on a second thread while the main thread encodes: numpy and
OpenCV release the GIL in their heavy loops, so on two cores drawing and
noise hide behind the encoder.
"""

from __future__ import annotations

import csv
import queue
import threading
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from cuespin.physics.scene import Scene
from cuespin.render.draw import FrameRenderer, FrameTruth, render_settings
from cuespin.render.timing import FrameTimes, constant_time_base, frame_times
from cuespin.videoio import quiet_native_stderr

LOSSLESS_CODECS = ("FFV1",)
LOSSY_CODECS = ("MJPG", "mp4v", "XVID", "H264")
# Written through PyAV (OpenCV's wheel cannot write H.264): codec name -> encoder.
PYAV_CODECS = {"H264": "libx264"}
H264_SUFFIXES = (".mp4", ".mov", ".mkv")
# Constant rate factor: the middle of what phones deliver (their hardware
# encoders land near x264's CRF 18-23 at their bit rates); see README.
H264_CRF = 20.0
# x264's speed preset: phones' hardware encoders compress about as well as
# its faster presets; measured in tests/test_video_io.py.
H264_PRESET = "veryfast"
_QUEUE_DEPTH = 8


class VideoError(RuntimeError):
    """The video could not be written (codec, path or OpenCV failure)."""


def open_writer(path: Path, codec: str, fps: float, size: tuple[int, int],
                is_color: bool = False) -> cv2.VideoWriter:
    """An OpenCV VideoWriter for 8-bit grey (or BGR) frames; raises VideoError if it won't open."""
    if len(codec) != 4:
        raise VideoError(f"codec must be a four-character code such as MJPG or FFV1, got {codec!r}")
    with quiet_native_stderr():
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), float(fps), size,
                                 isColor=is_color)
    if not writer.isOpened():
        raise VideoError(f"OpenCV cannot write codec {codec} to {path}; "
                         f"try MJPG (lossy) or FFV1 (lossless) in a .avi file")
    return writer


def truth_path(video: Path) -> Path:
    """``<video without extension>.truth.csv`` (CONVENTIONS.md)."""
    video = Path(video)
    return video.with_name(video.stem + ".truth.csv")


def write_truth_csv(path: Path, truth: FrameTruth) -> None:
    """Write the sidecar: ``frame,t,u_px,v_px,x_m,y_m,uc_px,vc_px`` per frame.

    ``u_px, v_px``: the silhouette's centroid; ``uc_px, vc_px``: the projected
    true centre (both averaged over the exposure), see :class:`FrameTruth`.
    """
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["frame", "t", "u_px", "v_px", "x_m", "y_m", "uc_px", "vc_px"])
        for k in range(len(truth.t)):
            w.writerow([k, repr(float(truth.t[k])), repr(float(truth.uv[k, 0])),
                        repr(float(truth.uv[k, 1])), repr(float(truth.xy[k, 0])),
                        repr(float(truth.xy[k, 1])), repr(float(truth.uvc[k, 0])),
                        repr(float(truth.uvc[k, 1]))])


class _OpenCvWriter:
    """An OpenCV VideoWriter (AVI codecs), opened on the first frame so grey
    and colour frames both work; OpenCV stamps frame ``k`` at ``k / fps``."""

    def __init__(self, path: Path, codec: str, fps: float, size: tuple[int, int]):
        self.path, self.codec, self.fps, self.size = path, codec, fps, size
        self.writer = None

    def write(self, frame: np.ndarray, k: int) -> None:
        if self.writer is None:
            self.writer = open_writer(self.path, self.codec, self.fps, self.size,
                                      is_color=frame.ndim == 3)
        self.writer.write(frame)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.release()


def _grey_luma() -> np.ndarray:
    ramp = np.tile(np.repeat(np.arange(256, dtype=np.uint8), 2), (2, 1))  # even-sized, 2x2 blocks
    yuv = cv2.cvtColor(cv2.cvtColor(ramp, cv2.COLOR_GRAY2BGR), cv2.COLOR_BGR2YUV_I420)
    return yuv[0, ::2].copy()


# Luma of each grey level, as OpenCV's BGR -> I420 gives it (16 + 219 g / 255).
_GREY_LUMA = _grey_luma()


def to_i420(frame: np.ndarray) -> np.ndarray:
    """A grey or BGR 8-bit frame as planar yuv420p (I420), BT.601 limited range.

    OpenCV's conversion round-trips every colour to within a grey level;
    libswscale's default (what PyAV's own reformat uses) shifts flat
    colours by up to 4 levels.  Grey frames take a lookup table with the
    same luma and neutral chroma.

    The chroma is each 2 x 2 block's mean, as an encoder's downsampling
    filter gives: OpenCV's own conversion takes the block's top-left pixel,
    which moved a ball tracked in a colour channel by ~0.5 px in u and v on
    every H.264 render (review7: realistic seed 0 shot 7, mean error +0.40 /
    +0.59 px; a colour edge 0.44 px, against 0.02-0.03 on MJPG).

    Returns
    -------
    ndarray of uint8, shape (3 height / 2, width)
    """
    if frame.ndim == 3:
        h, w = frame.shape[:2]
        out = cv2.cvtColor(frame, cv2.COLOR_BGR2YUV_I420)
        mean = cv2.resize(cv2.resize(frame, (w // 2, h // 2), interpolation=cv2.INTER_AREA), (w, h),
                          interpolation=cv2.INTER_NEAREST)
        out[h:] = cv2.cvtColor(mean, cv2.COLOR_BGR2YUV_I420)[h:]
        return out
    h, w = frame.shape
    out = np.full((h * 3 // 2, w), 128, dtype=np.uint8)
    out[:h] = _GREY_LUMA[frame]
    return out


class _PyAvWriter:
    """H.264 through PyAV's libx264 into MP4/MOV/MKV, each frame stamped with
    its own presentation timestamp (so a variable rate is stored exactly).

    yuv420p in limited (video) range, BT.601, as a phone writes it (see
    :func:`to_i420`).
    """

    def __init__(self, path: Path, codec: str, fps: float, size: tuple[int, int],
                 times: FrameTimes | None, crf: float):
        import av

        self.av = av
        self.times = times  # None: constant rate, pts = k in a 1 / fps time base
        time_base = times.time_base if times is not None else constant_time_base(fps)
        self.time_base = time_base
        try:
            with quiet_native_stderr():
                self.container = av.open(str(path), "w")
        except (av.error.FFmpegError, OSError, ValueError) as exc:
            raise VideoError(f"cannot write {path}: {exc}")
        try:
            stream = self.container.add_stream(PYAV_CODECS[codec], rate=Fraction(fps).limit_denominator(1_000_000))
            stream.width, stream.height = size
            stream.pix_fmt = "yuv420p"
            stream.time_base = time_base
            stream.codec_context.time_base = time_base
            stream.options = {"crf": f"{crf:g}", "preset": H264_PRESET}
        except Exception as exc:  # codec or muxer refused the settings
            self.container.close()
            raise VideoError(f"cannot write {codec} to {path}: {exc}")
        self.stream = stream

    def _mux(self, frame) -> None:
        for packet in self.stream.encode(frame):
            self.container.mux(packet)

    def write(self, frame: np.ndarray, k: int) -> None:
        vf = self.av.VideoFrame.from_ndarray(to_i420(frame), format="yuv420p")
        vf.pts = int(self.times.pts[k]) if self.times is not None else k
        vf.time_base = self.time_base
        self._mux(vf)

    def close(self) -> None:
        try:
            self._mux(None)  # flush the encoder's delayed frames
        finally:
            self.container.close()


def encode_frames(frames, path: Path, codec: str, fps: float, size: tuple[int, int],
                  progress=None, times: FrameTimes | None = None, crf: float = H264_CRF) -> int:
    """Encode an iterable of 8-bit frames, drawing them on a second thread.

    Parameters
    ----------
    frames : iterable of ndarray
        Frames, shape (height, width) grey or (height, width, 3) BGR, uint8;
        consumed on a worker thread.
    path : Path
        Output video file.
    codec : str
        FourCC written by OpenCV (:data:`LOSSLESS_CODECS`, :data:`LOSSY_CODECS`)
        or ``H264`` written by PyAV (libx264).
    fps : float
        Nominal frame rate (frames per second).
    size : (int, int)
        ``(width, height)`` in pixels.
    progress : callable, optional
        Called with 1 after each frame is written.
    times : FrameTimes, optional
        Each frame's presentation timestamp (H.264 only; OpenCV's AVI codecs
        stamp ``k / fps``).  Constant rate when absent.
    crf : float
        H.264 constant rate factor (0 lossless .. 51; lower is better).

    Returns
    -------
    int
        Frames written.
    """
    path = Path(path)
    if codec in PYAV_CODECS:
        if path.suffix.lower() not in H264_SUFFIXES:
            raise VideoError(f"codec {codec} is written to {', '.join(H264_SUFFIXES)} files, "
                             f"got {path.name}")
        writer = _PyAvWriter(path, codec, fps, size, times, crf)
    else:
        if times is not None and times.variable:
            raise VideoError(f"a variable frame rate (render.vfr_jitter) needs codec H264 in an .mp4: "
                             f"{codec} in an AVI stamps every frame k / fps")
        if len(codec) != 4:  # checked before the first frame is drawn
            raise VideoError(f"codec must be H264 or a four-character code such as MJPG or FFV1, "
                             f"got {codec!r}")
        writer = _OpenCvWriter(path, codec, fps, size)
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
            writer.write(fr, n)
            n += 1
            if progress is not None:
                progress(1)
    finally:
        try:
            writer.close()
        finally:
            # Unblock a producer still waiting on a full queue, then join it.
            while worker.is_alive():
                try:
                    q.get_nowait()
                except queue.Empty:
                    worker.join(0.01)
    if failure:
        raise failure[0]
    return n


def video_suffix(codec: str) -> str:
    """The file extension a codec is written with: ``.mp4`` for H264, else ``.avi``."""
    return ".mp4" if codec in PYAV_CODECS else ".avi"


def h264_crf(scene: Scene) -> float:
    """The scene's ``render.crf`` (default :data:`H264_CRF`), checked to lie in 0..51."""
    crf = scene.render.get("crf", H264_CRF)
    if isinstance(crf, bool) or not isinstance(crf, (int, float)) or not 0 <= crf <= 51:
        raise VideoError(f"render.crf: expected a number from 0 to 51, got {crf!r}")
    return float(crf)


def render_video(scene: Scene, path, progress=None, n_frames: int | None = None) -> FrameTruth:
    """Render a scene to a video file and write its ``.truth.csv`` beside it.

    Parameters
    ----------
    scene : Scene
        A scene with truth.
    path : str or Path
        Output video; its codec is ``render.codec`` (default MJPG; ``H264``
        writes an MP4 through PyAV at ``render.crf``, with the frame times of
        :func:`cuespin.render.timing.frame_times`, variable with
        ``render.vfr_jitter``).
    progress : callable, optional
        Called with 1 per frame written (e.g. a tqdm bar's ``update``).
    n_frames : int, optional
        Override the scene's video length.

    Returns
    -------
    FrameTruth
        The per-frame truth that was written to the sidecar; its ``t`` is
        each frame's time as the file stores it.
    """
    path = Path(path)
    codec = str(render_settings(scene)["codec"])
    crf = h264_crf(scene)
    renderer = FrameRenderer(scene, n_frames)
    times = frame_times(scene, renderer.n_frames)
    # The drawing loop took its times from the same function.
    assert np.array_equal(times.t, renderer.truth.t)
    cam = scene.camera
    if codec not in LOSSLESS_CODECS and (cam.width % 2 or cam.height % 2):
        raise VideoError(f"codec {codec} needs an even frame size, got {cam.width}x{cam.height}; "
                         f"make camera.width and camera.height even or use FFV1")
    n = encode_frames(renderer.frames(), path, codec, cam.fps, (cam.width, cam.height), progress,
                      times=times, crf=crf)
    if n != renderer.n_frames:
        raise VideoError(f"wrote {n} of {renderer.n_frames} frames to {path}")
    write_truth_csv(truth_path(path), renderer.truth)
    return renderer.truth


def read_truth_csv(path) -> dict[str, np.ndarray]:
    """Read a ``.truth.csv`` sidecar into arrays keyed by column name."""
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {name: np.atleast_1d(data[name]) for name in data.dtype.names}
