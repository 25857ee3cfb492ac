"""Opening a video and streaming its frames: every pixel format, and its frame times.

OpenCV decodes with its RGB conversion on, so every pixel format FFmpeg
knows (``bgr0``, ``yuv420p``, ``yuv444p``, ``gray``, ``rgb24``...) arrives
as 8-bit BGR; a video whose frames are grey (a ``gray`` stream, or colour
planes that all agree) is read as one channel.  PyAV reads what OpenCV
cannot open, and gives the container's presentation timestamps, from a
pass over the packets (no decoding: a few ms per thousand frames).

For the tracker (``FrameSource(planes=True)``) a 4:2:0 stream (``yuv420p``,
``yuvj420p``: MJPG, H.264, mp4v) is decoded by PyAV and handed over as its
planes (:class:`PlanarFrame`): the tracker looks at most frames through a
window around the ball, and the YUV to BGR conversion of the whole frame
was about half of decoding's CPU (H.264, tspeed10); the windows are
converted on demand.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from cuespin.videoio import quiet_native_stderr

# Codecs that store every pixel exactly (FFmpeg's names).
LOSSLESS_CODECS = {"ffv1", "huffyuv", "ffvhuff", "png", "rawvideo", "utvideo", "magicyuv", "qtrle",
                   "zlib", "r210", "v210", "libx264rgb"}
# Lossy codecs that code every frame on its own (FFmpeg's names and the
# FourCCs OpenCV reports): their error is not carried from frame to frame.
# Any other lossy codec (h264, hevc, vp9, av1, mpeg4...) predicts frames from
# others, and a moving ball's error is shared by neighbouring frames
# (recover.mle.INTER_CODEC_ACF, measured on H.264).
INTRA_CODECS = {"mjpeg", "mjpg", "jpeg", "mjpa", "mjpb", "jpeg2000", "mjp2", "prores", "apch", "apcn",
                "dnxhd", "avdn", "dvvideo", "dvsd"}
GREY_PIX_FMTS = {"gray", "gray8", "y8", "gray10le", "gray12le", "gray16le", "gray16be", "monow", "monob"}
# Pixel formats storing colour at half resolution both ways (4:2:0) besides
# those named ``*420*`` (FFmpeg's names): one chroma sample a 2 x 2 block.
CHROMA_420_PIX_FMTS = {"nv12", "nv21", "p010le", "p010be", "p016le", "p016be"}
# 8-bit 4:2:0 planar formats read as planes (PlanarFrame), and whether their
# levels are full range (JPEG's ``yuvj``) rather than BT.601's 16-235.
PLANAR_PIX_FMTS = {"yuv420p": False, "yuvj420p": True}
# Full-range (JPEG, ``yuvj``) levels mapped onto BT.601's 16-235 (Y) and
# 16-240 (chroma), rounded, so that OpenCV's 4:2:0 converter takes them: a
# whole 1280 x 640 frame ~3x cheaper than upsampling the chroma and
# converting JPEG's YCrCb (cv2.COLOR_YCrCb2BGR), for at most 2 levels
# against that exact conversion (the rounding, times BT.601's gains; measured).
FULL_TO_VIDEO_Y = np.clip(np.rint(16 + np.arange(256) * 219 / 255), 0, 255).astype(np.uint8)
FULL_TO_VIDEO_C = np.clip(np.rint(128 + (np.arange(256) - 128) * 224 / 255), 0, 255).astype(np.uint8)
# BT.601's grey level of each luma level with neutral chroma: what
# cv2.cvtColor's 4:2:0 conversion gives (a frame of the 256 levels converted).
VIDEO_Y_TO_GREY = cv2.cvtColor(np.concatenate([np.tile(np.arange(256, dtype=np.uint8), (2, 1)),
                                               np.full((1, 256), 128, np.uint8)]),
                               cv2.COLOR_YUV2BGR_I420)[0, :, 1].copy()
# Most a PlanarFrame's BGR level departs from OpenCV's decoding of the same
# frame (FFmpeg's swscale, whose fixed-point path comes out ~1 level lower
# than cv2.cvtColor's rounding, B, G and R alike: mean 0.7-1.7): 3 on H.264,
# mp4v (yuv420p) and MJPG (yuvj420p), over 100 frames and 2,000 windows of
# each of the speed benchmark's 1,000-frame files (1280 x 640; measured, yuv11).
BGR_LEVELS_TOL = 3

# A grey video's frames still decode to BGR when its stream is yuv (MJPG
# with neutral chroma); after YUV to BGR conversion the three planes agree
# exactly.  Checked on the first frame only.

try:  # OpenCV logs a warning per frame for some streams; failures are reported by us
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
except AttributeError:  # builds without the logging module
    pass


class TrackError(Exception):
    """The video cannot be tracked; the message is one line saying why."""


@dataclass(frozen=True)
class VideoInfo:
    """What the container says about a video stream.

    Attributes
    ----------
    width, height : int
        Frame size (px).
    n_frames : int
        Frames the container announces (0 when unknown).
    codec : str
        FFmpeg's codec name (``mjpeg``, ``ffv1``, ``h264``...), or a FourCC.
    pix_fmt : str
        FFmpeg's pixel format ('' when unknown).
    lossless : bool
        Every pixel is stored exactly.
    time_base : Fraction or None
        Unit of the presentation timestamps (s).
    backend : str
        ``cv2`` or ``av``: which decoder gives the frames in BGR (``cv2``
        whenever OpenCV opens the file).  A 4:2:0 stream PyAV opens is read
        as planes by PyAV whatever this says (:attr:`FrameSource.planar`).
    """

    width: int
    height: int
    n_frames: int
    codec: str
    pix_fmt: str
    lossless: bool
    time_base: Fraction | None
    backend: str

    @property
    def inter_frame(self) -> bool:
        """A lossy codec that predicts frames from other frames (not in
        :data:`INTRA_CODECS`): its error is shared between frames."""
        return not self.lossless and self.codec.strip().lower() not in INTRA_CODECS

    @property
    def chroma_block(self) -> int:
        """Side (px) of the pixel blocks sharing one chroma sample: 2 for a
        4:2:0 stream (MJPG from OpenCV's writer, H.264's yuv420p), 1
        otherwise or when the pixel format is unknown."""
        pf = self.pix_fmt.strip().lower()
        return 2 if "420" in pf or pf in CHROMA_420_PIX_FMTS else 1


def _check_path(path) -> Path:
    path = Path(path)
    if not path.exists():
        raise TrackError(f"video not found: {path}")
    if path.is_dir():
        raise TrackError(f"expected a video file, got a folder: {path}")
    return path


def _open_cv2(path: Path):
    with quiet_native_stderr():
        cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
        ok = cap.isOpened()
    if not ok:
        cap.release()
        return None
    return cap


def fourcc_of(cap: cv2.VideoCapture) -> str:
    """The stream's four-character code ('' if unknown)."""
    code = int(cap.get(cv2.CAP_PROP_FOURCC))
    return "".join(chr((code >> 8 * i) & 0xFF) for i in range(4)) if code > 0 else ""


def probe(path) -> VideoInfo:
    """Open a video's container and describe its stream, or raise :class:`TrackError`."""
    import av

    path = _check_path(path)
    info = None
    try:
        with quiet_native_stderr(), av.open(str(path)) as c:
            if c.streams.video:
                s = c.streams.video[0]
                cc = s.codec_context
                info = dict(width=int(cc.width), height=int(cc.height), n_frames=int(s.frames or 0),
                            codec=str(cc.name), pix_fmt=str(cc.pix_fmt or ""),
                            time_base=s.time_base)
    except (av.error.FFmpegError, OSError, ValueError):
        info = None
    cap = _open_cv2(path)
    if cap is None and info is None:
        raise TrackError(f"{path}: not a video OpenCV or PyAV can read")
    if info is None:  # OpenCV alone opens it
        fcc = fourcc_of(cap)
        info = dict(width=int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
                    height=int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)),
                    n_frames=max(int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), 0), codec=fcc.strip(),
                    pix_fmt="", time_base=None)
    if cap is not None:
        if info["n_frames"] <= 0:  # the container's count, else OpenCV's estimate
            info["n_frames"] = max(int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), 0)
        cap.release()
    lossless = info["codec"].lower() in LOSSLESS_CODECS or info["codec"].upper() in {"FFV1", "HFYU", "FFVH"}
    return VideoInfo(lossless=lossless, backend="cv2" if cap is not None else "av", **info)


def frame_times(path, info: VideoInfo, n: int, fps: float) -> np.ndarray:
    """Timestamps of frames ``0 .. n-1`` (s), by CONVENTIONS.md.

    ``k / fps``, unless the container's presentation timestamps, relative to
    frame 0, depart from it by more than one tick of the time base (a
    variable-frame-rate file): then those.  A pass over the packets without
    decoding; when timestamps are missing or do not count ``n`` frames,
    ``k / fps``.
    """
    nominal = np.arange(n) / fps
    if info.time_base is None or n == 0:
        return nominal
    import av

    try:
        with quiet_native_stderr(), av.open(str(path)) as c:
            s = c.streams.video[0]
            pts = [p.pts for p in c.demux(s) if p.size and p.pts is not None]
    except (av.error.FFmpegError, OSError, ValueError):
        return nominal
    if len(pts) < n:
        return nominal
    pts = np.sort(np.array(pts, dtype=np.int64))[:n]
    tb = info.time_base
    t = (pts - pts[0]) * float(tb)
    # Exact rational tick against k/fps: the tolerance is the rounding of
    # k/fps to whole ticks (half a tick; one, for muxers that truncate).
    if np.max(np.abs(t - nominal)) <= float(tb) * (1 + 1e-9):
        return nominal
    return t


class PlanarFrame:
    """A decoded 4:2:0 frame held as its planes, read as 8-bit BGR (h, w, 3).

    Indexing a window (``frame[v0:v1, u0:u1]``) converts that window only:
    the planes cropped at even coordinates (each chroma sample covers a 2 x 2
    block, repeated as OpenCV's decoder does) and converted by BT.601
    (``cv2.cvtColor``, ``COLOR_YUV2BGR_I420``); full-range (JPEG) levels are
    first mapped onto BT.601's (:data:`FULL_TO_VIDEO_Y`, ``_C``).
    ``np.asarray(frame)`` converts the whole frame once and keeps it.  The
    levels differ from OpenCV's decoding of the same file (FFmpeg's swscale)
    by at most :data:`BGR_LEVELS_TOL`.

    Parameters
    ----------
    i420 : ndarray, shape (3 h / 2, w), uint8
        The Y plane's rows, then U's and V's (PyAV's ``to_ndarray()``).
    full_range : bool
        Levels 0-255 (``yuvj420p``) rather than 16-235.
    """

    ndim = 3
    dtype = np.dtype(np.uint8)

    def __init__(self, i420: np.ndarray, full_range: bool):
        h, w = i420.shape[0] * 2 // 3, i420.shape[1]
        self.shape = (h, w, 3)
        self.full_range = full_range
        flat = i420.reshape(-1)
        q = h * w // 4
        self._y = i420[:h]
        self._u = flat[h * w:h * w + q].reshape(h // 2, w // 2)
        self._v = flat[h * w + q:].reshape(h // 2, w // 2)
        self._bgr = None  # the whole frame's BGR, once asked for
        self._last = None  # (v0, v1, u0, u1, BGR) of the last window converted

    def window(self, v0: int, v1: int, u0: int, u1: int) -> np.ndarray:
        """BGR of rows ``v0:v1`` and columns ``u0:u1`` (clipped to the frame), (v1 - v0, u1 - u0, 3)."""
        h, w = self.shape[:2]
        if self._bgr is not None:
            return self._bgr[v0:v1, u0:u1]
        if self._last is not None:
            # The tracker looks at a frame through nested windows (the search
            # box, then the ball's patch within it: 3 in 4 requests on the
            # speed benchmark's file lie within the frame's previous one).
            a0, a1, b0, b1, bgr = self._last
            if a0 <= v0 and v1 <= a1 and b0 <= u0 and u1 <= b1:
                return bgr[v0 - a0:v1 - a0, u0 - b0:u1 - b0]
        # Even corners: a chroma sample covers rows 2i, 2i+1 and columns 2j, 2j+1.
        a0, b0 = v0 & ~1, u0 & ~1
        a1, b1 = min(v1 + (v1 & 1), h), min(u1 + (u1 & 1), w)
        y = self._y[a0:a1, b0:b1]
        u = self._u[a0 // 2:a1 // 2, b0 // 2:b1 // 2]
        v = self._v[a0 // 2:a1 // 2, b0 // 2:b1 // 2]
        hh, ww = y.shape
        n, q = hh * ww, hh * ww // 4
        buf = np.empty((hh * 3 // 2, ww), np.uint8)  # OpenCV's I420 layout: Y, then U's and V's samples
        flat = buf.reshape(-1)
        if self.full_range:
            buf[:hh] = cv2.LUT(y, FULL_TO_VIDEO_Y)
            flat[n:n + q].reshape(hh // 2, ww // 2)[:] = cv2.LUT(u, FULL_TO_VIDEO_C)
            flat[n + q:].reshape(hh // 2, ww // 2)[:] = cv2.LUT(v, FULL_TO_VIDEO_C)
        else:
            buf[:hh] = y
            flat[n:n + q].reshape(hh // 2, ww // 2)[:] = u
            flat[n + q:].reshape(hh // 2, ww // 2)[:] = v
        bgr = cv2.cvtColor(buf, cv2.COLOR_YUV2BGR_I420)
        self._last = (a0, a1, b0, b1, bgr)
        return bgr[v0 - a0:v1 - a0, u0 - b0:u1 - b0]

    def grey(self) -> np.ndarray:
        """The frame's grey levels (h, w) when its chroma is neutral: the Y
        plane itself at full range (OpenCV's decoding of grey MJPG, to the
        level), else BT.601's gain on it (:data:`VIDEO_Y_TO_GREY`)."""
        if self.full_range:
            return self._y.copy()
        return cv2.LUT(self._y, VIDEO_Y_TO_GREY)

    def __getitem__(self, key):
        if isinstance(key, tuple) and len(key) == 2 and all(isinstance(k, slice) and k.step in (None, 1)
                                                             for k in key):
            v0, v1, _ = key[0].indices(self.shape[0])
            u0, u1, _ = key[1].indices(self.shape[1])
            if (v0, v1, u0, u1) != (0, self.shape[0], 0, self.shape[1]):
                return self.window(v0, max(v1, v0), u0, max(u1, u0))
        return np.asarray(self)[key]

    def __array__(self, dtype=None, copy=None):
        if self._bgr is None:
            self._bgr = self.window(0, self.shape[0], 0, self.shape[1])
            self._last = None
        return self._bgr if dtype is None else self._bgr.astype(dtype)


class FrameSource:
    """Frames of a video in order: 8-bit BGR (h, w, 3), or (h, w) when the video is grey.

    With ``planes``, a 4:2:0 colour stream PyAV opens arrives as
    :class:`PlanarFrame` (BGR by window, the tracker's reading).  Iterate it
    once; a decoding failure is raised from the iterator.
    """

    def __init__(self, path, info: VideoInfo, planes: bool = False):
        self.path = Path(path)
        self.info = info
        self.grey = info.pix_fmt in GREY_PIX_FMTS
        self._decided = self.grey  # grey-by-content is decided on the first frame
        # PyAV opened the file (probe read its stream) and the planes split evenly.
        self.planar = (planes and info.pix_fmt in PLANAR_PIX_FMTS and info.time_base is not None
                       and info.width % 2 == 0 and info.height % 2 == 0)

    def _grey_content(self, img) -> bool:
        return bool(np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 0], img[..., 2]))

    def _emit(self, img):
        if img.ndim == 3 and img.shape[2] == 1:
            img = img[:, :, 0]
        if img.ndim == 2:
            self.grey = True
            return img
        if img.shape[2] == 4:
            img = img[:, :, :3]
        if not self._decided:
            self.grey = self._grey_content(img)
            self._decided = True
        return cv2.extractChannel(img, 1) if self.grey else img

    def __iter__(self):
        if self.planar:
            yield from self._iter_planes()
        elif self.info.backend == "cv2":
            yield from self._iter_cv2()
        else:
            yield from self._iter_av()

    def _iter_cv2(self):
        cap = _open_cv2(self.path)
        if cap is None:
            raise TrackError(f"{self.path}: OpenCV cannot open the video")
        try:
            while True:
                with quiet_native_stderr():
                    ok, img = cap.read()
                if not ok or img is None:
                    return
                yield self._emit(img)
        finally:
            cap.release()

    def _iter_av(self):
        import av

        with quiet_native_stderr():
            c = av.open(str(self.path))
        try:
            s = c.streams.video[0]
            s.thread_type = "AUTO"
            fmt = "gray" if self.grey else "bgr24"
            for fr in c.decode(s):
                yield self._emit(fr.to_ndarray(format=fmt))
        except av.error.FFmpegError as exc:
            raise TrackError(str(exc)) from None
        finally:
            c.close()


    def _iter_planes(self):
        import av

        full_range = PLANAR_PIX_FMTS[self.info.pix_fmt]
        with quiet_native_stderr():
            c = av.open(str(self.path))
        try:
            s = c.streams.video[0]
            for fr in c.decode(s):
                if fr.format.name != self.info.pix_fmt:  # the stream changed format: BGR whole
                    yield self._emit(fr.to_ndarray(format="bgr24"))
                    continue
                frame = PlanarFrame(fr.to_ndarray(), full_range)
                if not self._decided:
                    self.grey = self._grey_content(np.asarray(frame))
                    self._decided = True
                # a grey video: one channel, as the other paths give it
                yield frame.grey() if self.grey else frame
        except av.error.FFmpegError as exc:
            raise TrackError(str(exc)) from None
        finally:
            c.close()


class ThreadedFrames:
    """A :class:`FrameSource` decoded on a second thread into a bounded queue.

    OpenCV and PyAV release the GIL while decoding, so decoding overlaps the
    tracker's work.  Iterating yields frames; a decoding failure arrives as
    the exception, raised from the iterator.  :meth:`close` stops the thread.
    """

    def __init__(self, source, maxsize: int):
        self.q: queue.Queue = queue.Queue(maxsize=max(int(maxsize), 2))
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, args=(source,), daemon=True)
        self._t.start()

    def _run(self, source):
        try:
            for img in source:
                while not self._stop.is_set():
                    try:
                        self.q.put(img, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if self._stop.is_set():
                    return
        except BaseException as exc:  # surfaced on the consumer's thread
            self.q.put(exc)
        finally:
            self.q.put(None)

    def __iter__(self):
        while True:
            item = self.q.get()
            if item is None:
                return
            if isinstance(item, BaseException):
                raise item
            yield item

    def close(self):
        self._stop.set()
        while self._t.is_alive():
            try:
                self.q.get_nowait()
            except queue.Empty:
                pass
            self._t.join(timeout=0.05)


__all__ = ["FrameSource", "PlanarFrame", "ThreadedFrames", "TrackError", "VideoInfo", "frame_times", "probe"]
