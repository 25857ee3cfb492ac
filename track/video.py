"""Reading a video and tracking the ball through it: the tracker's I/O edge.

Decoding runs on a second thread (OpenCV releases the GIL) from the start:
while it fills a bounded buffer, the main thread seeks a second reader to
frames spread over the video and learns the background; then it tracks
what the decoder delivers.  Frames are dropped as soon as they are tracked,
so memory is capped by the buffer, whatever the video's length.
"""

from __future__ import annotations

import csv
import os
import queue
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from cuespin.physics.scene import Scene
from cuespin.videoio import quiet_native_stderr
from cuespin.track.background import Background, FeltAccumulator, learn_background
from cuespin.track.model import refit_shift
from cuespin.track.tracker import OK, STATUS_TEXT, BallTracker, TrackerConfig

# Bytes of decoded frames the decoder may run ahead while the background is
# learnt.  OpenCV's seek decodes ~16 frames forward from an earlier one, so
# each background sample costs ~16 decodes; with this much room (366 frames
# at 1280 x 640) the sequential decoder does not stall meanwhile, and for a
# lossless codec, costly to decode, samples within it are taken from the
# buffer instead.  A fixed cap: memory does not grow with the video's length.
BUFFER_BYTES = 300 * 2**20

# Decoding grey video without RGB conversion hands back the luma plane and
# OpenCV logs a warning per frame saying so; the tracker wants exactly that.
try:
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
except AttributeError:  # builds without the logging module
    pass


class TrackError(Exception):
    """The video cannot be tracked; the message is one line saying why."""


@dataclass
class TrackResult:
    """The ball's track through a video.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Frame timestamps ``k / fps`` (s).
    uv : ndarray, shape (n, 2)
        Centre of the ball's image (px); NaN where not ``ok``.
    xy : ndarray, shape (n, 2)
        Centre on the table (m) through the inverse homography; NaN where not ok.
    ok : ndarray of bool, shape (n,)
    status : ndarray of int8, shape (n,)
        ``track.tracker`` status codes.
    stderr_px : ndarray, shape (n, 2)
        Standard error of ``uv`` from the disc fit (px); NaN with ``moments``.
    radius_px : float
    background : Background
    error : str
        Empty, or what went wrong: the video ended early (truncated or
        corrupt; the frames before it are still here) or no ball was found.
    seconds : dict
        Wall time of the background model and of the tracking pass (s).
    lossless : bool
        The video's codec is lossless.  A lossy codec's error is a function
        of the image, so frames of a resting ball share it: they are one
        measurement, not many.
    """

    t: np.ndarray
    uv: np.ndarray
    xy: np.ndarray
    ok: np.ndarray
    status: np.ndarray
    stderr_px: np.ndarray
    radius_px: float
    background: Background
    error: str = ""
    seconds: dict = field(default_factory=dict)
    lossless: bool = False

    @property
    def n_frames(self) -> int:
        return len(self.t)

    @property
    def centroid_noise_px(self) -> float:
        """Typical per-axis standard error of a centroid (px), NaN if unknown."""
        se = self.stderr_px[self.ok]
        return float(np.nanmedian(se)) if se.size and np.isfinite(se).any() else float("nan")

    def status_counts(self) -> dict[str, int]:
        """How many frames had each status."""
        vals, counts = np.unique(self.status, return_counts=True)
        return {STATUS_TEXT[int(v)]: int(c) for v, c in zip(vals, counts)}


LOSSLESS_FOURCC = {"FFV1", "HFYU", "FFVH", "MPNG", "PNG ", "Y800", "GREY", "RGBA", "I420", "IYUV", "YV12"}


def fourcc_of(cap: cv2.VideoCapture) -> str:
    """The stream's four-character code ('' if unknown)."""
    code = int(cap.get(cv2.CAP_PROP_FOURCC))
    return "".join(chr((code >> 8 * i) & 0xFF) for i in range(4)) if code > 0 else ""


def open_video(path) -> cv2.VideoCapture:
    """Open a video for reading or raise :class:`TrackError` with one line."""
    path = Path(path)
    if not path.exists():
        raise TrackError(f"video not found: {path}")
    if path.is_dir():
        raise TrackError(f"expected a video file, got a folder: {path}")
    with quiet_native_stderr():
        cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
        ok = cap.isOpened()
    if not ok:
        raise TrackError(f"{path}: not a video OpenCV can read")
    # Grey videos decode straight to one channel without RGB conversion.
    cap.set(cv2.CAP_PROP_CONVERT_RGB, 0.0)
    return cap


def to_grey(img: np.ndarray) -> np.ndarray:
    """An 8-bit grey image from whatever the decoder returned."""
    if img.ndim == 2:
        return img
    if img.shape[2] == 1:
        return img[:, :, 0]
    return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


def sample_frames(path, idx, buffered=None) -> tuple[np.ndarray, np.ndarray]:
    """Grey frames at the given indices (those that decode) and their indices.

    ``buffered``, when given, is a :class:`_Buffered`: frames below its
    ``limit`` are taken from the sequential decoder's buffer; only the others
    cost a seek, and a seek decodes ~16 frames.
    """
    idx = [int(i) for i in idx]
    limit = buffered.limit if buffered is not None else 0
    found = {}
    seek = [i for i in idx if i >= limit]
    if seek:  # first, while the decoder fills its buffer
        cap = open_video(path)
        try:
            with quiet_native_stderr():
                for i in seek:
                    cap.set(cv2.CAP_PROP_POS_FRAMES, float(i))
                    ok, img = cap.read()
                    if ok and img is not None:
                        found[i] = to_grey(img)
        finally:
            cap.release()
    for i in idx:
        if i < limit:
            img = buffered(i)
            if img is not None:
                found[i] = img
    if not found:
        return np.zeros((0, 0, 0), np.uint8), np.zeros(0, int)
    got = sorted(found)
    return np.stack([found[i] for i in got]), np.array(got)


def learn_video_background(path, n_frames: int, radius_px: float, n_samples: int,
                           buffered=None) -> Background:
    """Background from ``n_samples`` frames spread over the video, plus as many
    again where a resting ball hid the felt from most of the first ones
    (``buffered`` as in :func:`sample_frames`)."""
    idx = np.unique(np.linspace(0, max(n_frames - 1, 0), n_samples).round().astype(int))
    samples, idx = sample_frames(path, idx, buffered)
    if len(samples) == 0:
        raise TrackError(f"{path}: no frame could be decoded (corrupt video?)")
    bg = learn_background(samples, radius_px)
    if bg.weak_samples.any():
        # Sample the stretch of video whose frames showed the hidden felt,
        # reaching half a spacing beyond it on each side.
        shown = idx[bg.weak_samples]
        gap = max(n_frames // max(n_samples - 1, 1), 1)
        lo, hi = max(shown.min() - gap // 2, 0), min(shown.max() + gap // 2, n_frames - 1)
        extra = np.setdiff1d(np.linspace(lo, hi, n_samples).round().astype(int), idx)
        more, extra = sample_frames(path, extra, buffered)
        if len(more):
            bg = learn_background(np.concatenate([samples, more]), radius_px)
    return bg


class _Buffered:
    """Frames from the decoder's queue before anything was taken from it.

    Frames below ``limit`` (the queue's size) always arrive, since the
    decoder can hold them without a consumer, so waiting for them cannot
    block; ``self(k)`` is None if the video ends first.
    """

    def __init__(self, q: queue.Queue):
        self.q = q
        self.limit = q.maxsize - 1

    def __call__(self, k: int):
        q = self.q
        if k >= self.limit:
            return None

        def ready():
            return len(q.queue) > k or (len(q.queue) > 0 and not isinstance(q.queue[-1], np.ndarray))

        with q.not_empty:
            q.not_empty.wait_for(ready)
            item = q.queue[k] if len(q.queue) > k else None
        return item if isinstance(item, np.ndarray) else None


def _decode(cap: cv2.VideoCapture, q: queue.Queue, stop: threading.Event):
    try:
        with quiet_native_stderr():
            while not stop.is_set():
                ok, img = cap.read()
                if not ok or img is None:
                    break
                q.put(to_grey(img))
    except Exception as exc:  # surfaced as the end of the video
        q.put(exc)
    finally:
        q.put(None)


def _read_one(cap: cv2.VideoCapture):
    """The next grey frame on the calling thread: None at the end, the
    exception if decoding failed (as the decoder thread delivers them)."""
    try:
        with quiet_native_stderr():
            ok, img = cap.read()
    except Exception as exc:
        return exc
    return to_grey(img) if ok and img is not None else None


def _stop_decoder(worker, q, stop, cap):
    stop.set()
    while worker.is_alive():  # unblock a decoder waiting on a full queue
        try:
            q.get_nowait()
        except queue.Empty:
            pass
        worker.join(timeout=0.05)
    cap.release()


def track_video(path, scene: Scene, config: TrackerConfig = TrackerConfig(),
                progress=None) -> TrackResult:
    """Track the ball through a video.

    Parameters
    ----------
    path : str or Path
        Any video OpenCV reads.
    scene : Scene
        Only ``physics`` and ``camera`` are used (never ``render``).
    config : TrackerConfig
    progress : callable, optional
        ``progress(n)`` after each ``n`` frames.

    Returns
    -------
    TrackResult

    Raises
    ------
    TrackError
        Missing or unreadable file, zero frames, or a frame size that
        disagrees with the scene.  A video that ends early or shows no ball
        still returns a result, with ``error`` saying so.
    """
    cam = scene.camera
    cap = open_video(path)
    n_hint = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    lossless = fourcc_of(cap).upper() in LOSSLESS_FOURCC
    w = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
    h = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    if n_hint <= 0 and w == 0:
        cap.release()
        raise TrackError(f"{path}: the video has no frames")
    cam = cam.with_size(w, h)  # a scene may leave the size to the video (CONVENTIONS.md)
    if (w, h) != (cam.width, cam.height):
        cap.release()
        raise TrackError(f"{path}: frames are {w}x{h} but the scene's camera says "
                         f"{cam.width}x{cam.height}; is this the right scene file?")
    center = cam.to_table([[cam.width / 2, cam.height / 2]])[0]
    radius_px = scene.physics.R * cam.px_per_m(center)

    q: queue.Queue = queue.Queue(maxsize=max(16, BUFFER_BYTES // (w * h)))
    stop = threading.Event()
    worker = threading.Thread(target=_decode, args=(cap, q, stop), daemon=True)
    if config.threaded:
        worker.start()
    t_start = time.perf_counter()
    try:
        # With a lossless codec (FFV1 decodes at ~18 ms of CPU a frame, on
        # both cores) a seek's ~16 decodes cost more than waiting for the
        # decoder to reach a sample, so samples it is about to hold anyway
        # are taken from its queue.  Lossy intra codecs (MJPG: ~2.6 ms) seek,
        # beside the decoder, and tracking starts sooner.
        buffered = _Buffered(q) if config.threaded and lossless else None
        bg = learn_video_background(path, max(n_hint, 1), radius_px, config.n_background, buffered)
    except BaseException:
        _stop_decoder(worker, q, stop, cap)
        raise
    t_bg = time.perf_counter() - t_start
    tracker = BallTracker(bg, radius_px, cam.exposure_s * cam.fps, config)
    uv, se, status = [], [], []
    t_start = time.perf_counter()
    error = ""
    k = 0
    felt = FeltAccumulator((cam.height, cam.width))
    fits = []  # (frame index, the fit's state) for the final background correction
    try:
        while True:
            item = q.get() if config.threaded else _read_one(cap)
            if item is None:
                break
            if isinstance(item, Exception):
                error = f"decoding failed at frame {k}: {item}"
                break
            if item.shape != (cam.height, cam.width):
                error = f"frame {k} has size {item.shape[1]}x{item.shape[0]}"
                break
            # With nothing moving there is no ball to separate from the felt.
            obs = tracker.step(k, item) if bg.polarity else tracker.nothing()
            if obs.status == OK:
                blur_len = np.hypot(*tracker.last_fit[5]) if tracker.last_fit else 0.0
                felt.add(item, obs.uv, radius_px + 0.5 * blur_len + 1.5)
                if tracker.last_fit is not None:
                    fits.append((k, tracker.last_fit))
            uv.append(obs.uv)
            se.append(obs.stderr)
            status.append(obs.status)
            k += 1
            if progress is not None and k % 64 == 0:
                progress(64)
    finally:
        _stop_decoder(worker, q, stop, cap)
    if progress is not None and k % 64:
        progress(k % 64)
    if k == 0:
        raise TrackError(f"{path}: the video has no frames that decode")
    # FFmpeg's frame count is exact for intact intra-coded files; a stream
    # that ends well short of it was cut off or is corrupt.
    if not error and n_hint > 0 and k < n_hint - 1:
        error = f"the video ends at frame {k} of {n_hint} (truncated or corrupt)"
    uv = np.array(uv, float).reshape(-1, 2)
    if fits and felt.n >= 20:
        # Every tracked frame's felt, averaged: correct each disc fit for it.
        better = felt.felt(bg.image)
        for kk, (pu, pv, h, w, c, b, G, fb) in fits:
            old = bg.image[pv:pv + h, pu:pu + w]
            new = better[pv:pv + h, pu:pu + w]
            uv[kk] = c + refit_shift(old, new, pu, pv, c, b, G, radius_px, fb)
        bg = Background(image=better, sigma=bg.sigma, polarity=bg.polarity, contrast=bg.contrast,
                        n_samples=bg.n_samples, path_pixels=bg.path_pixels,
                        weak_samples=bg.weak_samples)
    t_track = time.perf_counter() - t_start
    status = np.array(status, np.int8)
    ok = status == OK
    if not ok.any():
        why = (" (the ball never moved, or is not in view; do physics.R and camera.homography "
               "match the video?)")
        error = f"no ball found in any of {k} frames" + (f"; {error}" if error else why)
    xy = np.full_like(uv, np.nan)
    xy[ok] = cam.to_table(uv[ok])
    return TrackResult(t=cam.frame_times(k), uv=uv, xy=xy, ok=ok, status=status,
                       stderr_px=np.array(se, float).reshape(-1, 2), radius_px=radius_px,
                       background=bg, error=error,
                       seconds={"background": t_bg, "track": t_track}, lossless=lossless)


def write_track_csv(path, result: TrackResult) -> None:
    """Write ``frame,t,u_px,v_px,x_m,y_m,ok`` (CONVENTIONS.md), atomically.

    Rows with ``ok`` 0 have empty coordinates.
    """
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "t", "u_px", "v_px", "x_m", "y_m", "ok"])
        for k in range(result.n_frames):
            if result.ok[k]:
                u, v = result.uv[k]
                x, y = result.xy[k]
                w.writerow([k, repr(float(result.t[k])), repr(float(u)), repr(float(v)),
                            repr(float(x)), repr(float(y)), 1])
            else:
                w.writerow([k, repr(float(result.t[k])), "", "", "", "", 0])
    os.replace(tmp, path)


def read_track_csv(path) -> dict[str, np.ndarray]:
    """Read a track CSV; empty coordinates become NaN."""
    data = np.genfromtxt(path, delimiter=",", names=True, filling_values=np.nan)
    return {name: np.atleast_1d(data[name]) for name in data.dtype.names}


__all__ = ["TrackError", "TrackResult", "open_video", "read_track_csv", "track_video",
           "write_track_csv"]
