"""Opening a video and streaming its frames: every pixel format, and its frame times.

OpenCV decodes with its RGB conversion on, so every pixel format FFmpeg
knows (``bgr0``, ``yuv420p``, ``yuv444p``, ``gray``, ``rgb24``...) arrives
as 8-bit BGR; a video whose frames are grey (a ``gray`` stream, or colour
planes that all agree) is read as one channel.  PyAV reads what OpenCV
cannot open, and gives the container's presentation timestamps, from a
pass over the packets (no decoding: a few ms per thousand frames).

For the tracker (``FrameSource(planes=True)``, or ``planes=None``) a 4:2:0
stream (``yuv420p``, ``yuvj420p``: MJPG, H.264, mp4v) is decoded by PyAV
and handed over as its planes (:class:`PlanarFrame`): the tracker looks at most frames through a window
around the ball, and the YUV to BGR conversion of the whole frame was about
half of decoding's CPU (H.264, tspeed10); the windows are converted on
demand, by swscale's own arithmetic (:func:`swscale_terms`), so the levels
are OpenCV's to the bit and the tracks the same.
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


# Subsampled formats whose decoding does not repeat each chroma sample over
# its block but interpolates it (FFmpeg's swscale has no unscaled converter
# to BGR for them): a colour edge through FFV1 yuv440p came back spread over
# 4-5 rows, and the tracker's fits on the 1 x 2 blocks' means were further
# off than on pixels (tests/test_track_formats.py's yellow-on-grey scene,
# RMSE 0.0165 -> 0.0447 px; docs/measurements.md, yuv422), so they fit
# pixels there.  yuv411p interpolates too (an edge spread over ~8 columns in
# pairs), but its 4 x 1 blocks' fits were nearer than the pixels' (0.075 ->
# 0.040 px, err/se 1.50 -> 0.96) and its 2 x 1 pairs' far off (1.9 px).
CHROMA_PIXEL_FIT_PIX_FMTS = {"yuv440p", "yuvj440p"}
# The largest side (px) of a square block the fits take in place of an
# oblong chroma block that divides it: 4:2:2's 2 x 1 samples averaged in
# 2 x 2 are still exact block means, and on a square grid the look's
# quadratic term (model.streak_model's |X|^2 / r^2) is the pixels' own;
# on the 2 x 1 grid it is not, and the shaded realistic seed 0 shots 7 and
# 12 through MJPG yuvj422p were 0.22 px off in u (RMSE 0.158 / 0.171 px,
# pixels 0.132 / 0.153, 2 x 2 0.052 / 0.053; FFV1 yuv422p 0.076 / 0.041,
# 2 x 2 0.025 / 0.031).  4:1:1's 4 x 4 leaves a 6-9 px ball 3-4 blocks
# across: 0.302 / 0.390 px against 4 x 1's 0.171 / 0.106 (FFV1 yuv411p),
# so it keeps 4 x 1 (docs/measurements.md, yuv422).
FIT_SQUARE_MAX_PX = 2
# What a track says of its stated errors when its chroma is shared over more
# pixels along an axis than FIT_SQUARE_MAX_PX (4:1:1: DV's yuv411p; 4:1:0:
# yuv410p): the decoder interpolates that chroma over ~8 px, its blocks'
# fits model 4-px means on an oblong grid where the look's quadratic term
# is not round, and which channel the track is fitted in (one that sees
# luma, fitted on pixels with the chroma counted as independent per pixel,
# or a luma-blind one on the blocks) depends on the noise draw.  Measured on
# test_track_formats' small scene (FFV1, seeds 1-5 x noise 0.5 / 2 / 5),
# the error over the stated error per axis was 0.41-0.49 (v) and 1.22-1.30
# (u) where the channel was luma-blind, 1.08-1.73 where it saw luma (4:1:1),
# 0.78-3.69 (4:1:0, fitted on 4 x 4 blocks, frames lost and up to 1.0 px
# off), 1.9-3.0 on realistic 4:1:1 shots (docs/measurements.md, yuv422 and
# fix411): no one variance factor states it, so none is applied and the
# track says so.
UNCALIBRATED_CHROMA_WARNING = ("stated errors not calibrated: the video's {pix_fmt} chroma is shared over "
                               "{bx} x {by} pixels and interpolated by the decoder, which the tracker's "
                               "error model does not describe (measured error / stated 0.4-3.7 per axis); "
                               "treat every stated error, the recovery's too, as a rough guide")


def chroma_subsampling(pix_fmt: str) -> tuple[int, int]:
    """Pixels across and down sharing one chroma sample in FFmpeg's pixel
    format ``pix_fmt``: (2, 2) for 4:2:0 (``yuv420p``, ``yuvj420p``,
    ``nv12``), (2, 1) for 4:2:2 (``yuv422p``, ``yuvj422p``), (4, 1) for
    4:1:1 (``yuv411p``, DV), (1, 2) for 4:4:0, (1, 1) for 4:4:4, RGB, grey
    or an unknown or empty name.  From PyAV's description of the format
    (its chroma planes' size against the luma's; PyAV is a dependency, and
    every name the reader reports is FFmpeg's, which PyAV knows)."""
    import av

    pf = pix_fmt.strip().lower()
    if not pf:
        return 1, 1
    n = 48  # a multiple of every subsampling factor FFmpeg has (1, 2, 4)
    try:
        comps = av.VideoFormat(pf, n, n).components
        return (n // int(comps[1].width), n // int(comps[1].height)) if len(comps) >= 3 else (1, 1)
    except (ValueError, TypeError, ZeroDivisionError):  # a name FFmpeg does not know
        return 1, 1
# 8-bit 4:2:0 planar formats read as planes (PlanarFrame), and whether their
# levels are full range (JPEG's ``yuvj``) rather than BT.601's 16-235.
PLANAR_PIX_FMTS = {"yuv420p": False, "yuvj420p": True}
# Those read as planes unless told otherwise (FrameSource(planes=None)):
# H.264's and mp4v's (yuv420p) and MJPG's (yuvj420p): the planes save the
# whole frame's conversion and PyAV decodes them for less CPU than OpenCV
# (the tracking run's CPU on the speed benchmark's 1,000-frame files,
# medians: H.264 3.21 -> 2.29 s, mp4v 3.77 -> 3.13, MJPG 4.30 -> 3.65;
# speed13).  BT.601's and BT.709's coefficients are known here (the frame's
# colour matrix picks them, :data:`SWS_MATRICES`): a BT.709-tagged file
# (H.264 from phones) is read as planes too; a stream OpenCV converts
# otherwise (another matrix) fails the first-frame check and is read
# through OpenCV, exact but without the gain.
PLANAR_DEFAULT_PIX_FMTS = frozenset(PLANAR_PIX_FMTS)  # every one read as planes, since speed13
# FFmpeg's YUV -> RGB coefficients (libswscale/yuv2rgb.c,
# ff_yuv2rgb_coeffs[SWS_CS_*]: crv, cbu, cgu, cgv in 16.16 fixed point).
# BT.601's is swscale's default, what OpenCV converts an untagged stream
# with; BT.709's what OpenCV (and PyAV) convert a BT.709-tagged one with
# (all 40 of 40 frames of a libx264 bt709 file equal OpenCV's to the bit:
# review 10b, ``tests/test_track_formats.py``).
SWS_ITU601 = (104597, 132201, 25675, 53279)
SWS_ITU709 = (117489, 138438, 13975, 34925)
SWS_COEFFS = {"bt601": SWS_ITU601, "bt709": SWS_ITU709}
# FFmpeg's AVColorSpace codes (a frame's ``colorspace`` in PyAV) of the
# matrices known here; any other (unspecified, SMPTE 170M, BT.2020...)
# keeps BT.601's, swscale's default, and the first-frame check guards it.
SWS_MATRICES = {1: "bt709"}  # AVCOL_SPC_BT709


def swscale_terms(full_range: bool, matrix: str = "bt601"):
    """Each channel's luma and chroma terms in FFmpeg swscale's unscaled
    4:2:0 -> BGR24 conversion (what ``cv2.VideoCapture`` hands back): the
    16-bit coefficients ``ff_yuv2rgb_c_init_tables`` derives (``roundToInt16``
    of the 16.16 value times 2^13; limited range scales luma by 255/219 from
    16, full range the chroma by 224/255) applied as the x86 SIMD path does
    (``yuv_2_rgb.asm``: levels times 8, less the offset, ``pmulhw``, i.e.
    the product's floor / 2^16).  B = sat(fy[Y] + bu[U]), G = sat(fy[Y] +
    guv[U, V]), R = sat(fy[Y] + rv[V]), saturated to 0-255.  Equal to
    OpenCV's decoding for every one of the 2^24 (Y, U, V) of a lossless
    file, both ranges (yuv420p by FFV1, yuvj420p by lossless JPEG;
    ``tests/test_track_formats.py``); a video is read as planes only where
    its first frame agrees (:class:`FrameSource`).  BT.709's row
    (``matrix="bt709"``) by the same arithmetic: OpenCV's levels on a
    BT.709-tagged H.264 file, every frame (``tests/test_track_formats.py``).

    Parameters
    ----------
    full_range : bool
        Levels 0-255 (``yuvj420p``) rather than 16-235.
    matrix : str
        A key of :data:`SWS_COEFFS`: ``"bt601"`` or ``"bt709"``.

    Returns
    -------
    fy, bu, rv : ndarray, (256,) int32
    guv : ndarray, (256, 256) int32, indexed [U, V]
    """
    k = SWS_COEFFS[matrix]
    crv, cbu, cgu, cgv = k[0], k[1], -k[2], -k[3]
    if full_range:
        cy, oy = 1 << 16, 0
        # C's integer division truncates toward zero
        crv, cbu, cgu, cgv = (int(np.trunc(x * 224 / 255)) for x in (crv, cbu, cgu, cgv))
    else:
        cy, oy = (1 << 16) * 255 // 219, 16 << 16

    def r16(x):  # roundToInt16(x * 2^13)
        return (int(x) * (1 << 13) + (1 << 15)) >> 16

    lv = 8 * np.arange(256, dtype=np.int64)
    c = lv - 1024  # chroma times 8, less 128 * 8
    fy = ((lv - ((oy * 8 + (1 << 15)) >> 16)) * r16(cy)) >> 16
    bu, gu, gv, rv = ((c * r16(k)) >> 16 for k in (cbu, cgu, cgv, crv))
    return (fy.astype(np.int32), bu.astype(np.int32), (gu[:, None] + gv[None, :]).astype(np.int32),
            rv.astype(np.int32))


# 0-255 saturation of a channel's sum + 512 (its range: -19 + -271 to 278 + 271).
SAT_512 = np.clip(np.arange(-512, 1024), 0, 255).astype(np.uint8)

# A grey video's frames still decode to BGR when its stream is yuv (MJPG
# with neutral chroma); after YUV to BGR conversion the three planes agree
# exactly.  A colour video's black (or any blank) frame is neutral too, so a
# blank frame decides nothing: the first frame whose planes differ makes the
# video colour, the first neutral frame with content (levels spanning more
# than BLANK_SPREAD_LEVELS) makes it grey.  Undecided frames are held, at
# most GREY_UNDECIDED_BYTES of them; then the video is read as colour (a
# grey video read as BGR loses nothing but time; a colour one read as its G
# plane loses the ball's colour contrast: review 11a); blank to the end, grey.
# 32 levels (not measured: a choice): a fade's dark frame through MJPG keeps
# neutral chroma with luma spanning a few levels; a grey video whose frames
# span fewer (a ball/felt contrast under 32 with little noise) is only held
# longer, then read as colour, the same levels three times.
BLANK_SPREAD_LEVELS = 32


def blank_frame(img) -> bool:
    """Whether a frame is blank: its levels (every channel's) span at most
    :data:`BLANK_SPREAD_LEVELS` (a black lead-in, a fade's dark frame).  It
    shows neither ball nor felt, so it decides nothing here and the tracker
    learns nothing from it (``track.video``).

    Parameters
    ----------
    img : ndarray, shape (h, w) or (h, w, 3), uint8, or PlanarFrame
        One decoded frame.
    """
    h, w = img.shape[:2]
    # The middle row and column first: most frames span more there, and a
    # planar frame then converts those strips only, not the whole frame
    # (each when asked for: the row decides most frames, and a planar
    # frame's column took ~50 us to convert, measured on the speed file).
    for strip in (lambda: img[h // 2:h // 2 + 1, :], lambda: img[:, w // 2:w // 2 + 1]):
        strip = np.asarray(strip())
        if strip.size and int(strip.max()) - int(strip.min()) > BLANK_SPREAD_LEVELS:
            return False
    a = np.asarray(img)
    return a.size == 0 or int(a.max()) - int(a.min()) <= BLANK_SPREAD_LEVELS


# 64 MB: 23 frames of 1280 x 720 BGR, 8 of 4K; inside the tracker's
# look-ahead budget (track.video.LOOKAHEAD_BYTES, 384 MB).
GREY_UNDECIDED_BYTES = 64 << 20

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
    def chroma_block(self) -> tuple[int, int]:
        """The pixel blocks sharing one chroma sample, (across, down) px
        (:func:`chroma_subsampling` of the stream's pixel format): (2, 2)
        for 4:2:0 (MJPG from OpenCV's writer, H.264's yuv420p), (2, 1) for
        4:2:2 (MJPG from cameras, ``yuvj422p``), (4, 1) for 4:1:1 (DV),
        (1, 1) for 4:4:4, RGB, grey or an unknown pixel format."""
        return chroma_subsampling(self.pix_fmt)

    @property
    def fit_block(self) -> tuple[int, int]:
        """The blocks the tracker's fits model through a luma-blind channel
        (:func:`cuespin.track.model.fit_disc`'s ``block``): the square of
        the chroma block's longer side where that is at most
        :data:`FIT_SQUARE_MAX_PX` (4:2:0 and 4:2:2: (2, 2)), else the chroma
        block itself (4:1:1: (4, 1)); pixels, (1, 1), for a format in
        :data:`CHROMA_PIXEL_FIT_PIX_FMTS` (4:4:0)."""
        if self.pix_fmt.strip().lower() in CHROMA_PIXEL_FIT_PIX_FMTS:
            return 1, 1
        bx, by = self.chroma_block
        s = max(bx, by)
        return (s, s) if s <= FIT_SQUARE_MAX_PX else (bx, by)

    @property
    def error_warning(self) -> str:
        """Empty, or why the tracker's stated errors on this stream are not
        calibrated (:data:`UNCALIBRATED_CHROMA_WARNING`): its chroma block
        has a side longer than :data:`FIT_SQUARE_MAX_PX` (4:1:1, 4:1:0)."""
        bx, by = self.chroma_block
        if max(bx, by) <= FIT_SQUARE_MAX_PX:
            return ""
        return UNCALIBRATED_CHROMA_WARNING.format(pix_fmt=self.pix_fmt.strip().lower(), bx=bx, by=by)


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

    Indexing a window (``frame[v0:v1, u0:u1]``) converts that window only,
    by swscale's arithmetic (:func:`swscale_terms`, compiled:
    :func:`cuespin.track.window.yuv420_bgr`); ``np.asarray(frame)`` converts
    the whole frame once (by PyAV's swscale when the frame is PyAV's, the
    same levels) and keeps it.  The levels are OpenCV's decoding of the same
    file, to the bit, wherever OpenCV converts with swscale's arithmetic
    and the frame's colour matrix is one known here (BT.601, BT.709:
    ``matrix``; :class:`FrameSource` checks a video's first frame).

    Parameters
    ----------
    planes : av.VideoFrame or ndarray, shape (3 h / 2, w), uint8
        PyAV's decoded frame (its planes read in place), or the Y plane's
        rows, then U's and V's (PyAV's ``to_ndarray()``).
    full_range : bool
        Levels 0-255 (``yuvj420p``) rather than 16-235.
    matrix : str
        The colour matrix's coefficients, a key of :data:`SWS_COEFFS`.
    """

    ndim = 3
    dtype = np.dtype(np.uint8)

    def __init__(self, planes, full_range: bool, matrix: str = "bt601"):
        self.full_range = full_range
        self.matrix = matrix
        if isinstance(planes, np.ndarray):
            self._av = None
            h, w = planes.shape[0] * 2 // 3, planes.shape[1]
            flat = planes.reshape(-1)
            q = h * w // 4
            self._y = planes[:h]
            self._u = flat[h * w:h * w + q].reshape(h // 2, w // 2)
            self._v = flat[h * w + q:].reshape(h // 2, w // 2)
        else:
            self._av = planes
            h, w = planes.height, planes.width
            # Each plane's rows at their stride (C-contiguous: the compiled
            # conversion indexes within the width).
            self._y, self._u, self._v = (np.frombuffer(p, np.uint8).reshape(-1, p.line_size)
                                         for p in planes.planes[:3])
        self.shape = (h, w, 3)
        self._bgr = None  # the whole frame's BGR, once asked for
        self._last = None  # (v0, v1, u0, u1, BGR) of the last window converted

    def window(self, v0: int, v1: int, u0: int, u1: int) -> np.ndarray:
        """BGR of rows ``v0:v1`` and columns ``u0:u1``, clipped to the frame
        (the compiled conversion has no bounds checks: review 10b), (v1 - v0,
        u1 - u0, 3) after clipping."""
        h, w = self.shape[:2]
        v0, v1 = min(max(v0, 0), h), min(max(v1, 0), h)
        u0, u1 = min(max(u0, 0), w), min(max(u1, 0), w)
        v1, u1 = max(v1, v0), max(u1, u0)
        if self._bgr is not None:
            return self._bgr[v0:v1, u0:u1]
        if self._last is not None:
            # The tracker looks at a frame through nested windows (the search
            # box, then the ball's patch within it: 3 in 4 requests on the
            # speed benchmark's file lie within the frame's previous one).
            a0, a1, b0, b1, bgr = self._last
            if a0 <= v0 and v1 <= a1 and b0 <= u0 and u1 <= b1:
                return bgr[v0 - a0:v1 - a0, u0 - b0:u1 - b0]
        from cuespin.track.window import yuv420_bgr

        fy, bu, guv, rv = _TERMS[self.full_range, self.matrix]
        bgr = yuv420_bgr(self._y, self._u, self._v, v0, u0, np.empty((v1 - v0, u1 - u0, 3), np.uint8),
                         fy, bu, guv, rv, SAT_512)
        self._last = (v0, v1, u0, u1, bgr)
        return bgr

    def grey(self) -> np.ndarray:
        """The frame's green channel (h, w), as OpenCV's decoding of a grey
        video is read: by table from the Y plane when the chroma is
        neutral (every chroma term 0), else the whole frame's."""
        h, w = self.shape[:2]
        u, v = self._u[:h // 2, :w // 2], self._v[:h // 2, :w // 2]
        if not (np.all(u == 128) and np.all(v == 128)):
            return cv2.extractChannel(np.asarray(self), 1)
        return cv2.LUT(self._y[:h, :w], _GREY[self.full_range])

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
            if self._av is not None:
                self._bgr = self._av.to_ndarray(format="bgr24")
            else:
                self._bgr = self.window(0, self.shape[0], 0, self.shape[1])
            self._last = None
        return self._bgr if dtype is None else self._bgr.astype(dtype)


# swscale's terms by (full range, matrix), and the grey level of each luma
# level with neutral chroma (the luma term: the same for every matrix).
_TERMS = {(r, m): swscale_terms(r, m) for r in (False, True) for m in SWS_COEFFS}
_GREY = {r: np.clip(_TERMS[r, "bt601"][0], 0, 255).astype(np.uint8) for r in (False, True)}


class FrameSource:
    """Frames of a video in order: 8-bit BGR (h, w, 3), or (h, w) when the video is grey.

    With ``planes``, a 4:2:0 colour stream PyAV opens arrives as
    :class:`PlanarFrame` (BGR by window, the tracker's reading), OpenCV's
    levels to the bit (else, checked on the first frame, OpenCV's decoding);
    with ``planes=None``, those of :data:`PLANAR_DEFAULT_PIX_FMTS` only.
    Iterate it once; a decoding failure is raised from the iterator.
    """

    def __init__(self, path, info: VideoInfo, planes: bool | None = False):
        self.path = Path(path)
        self.info = info
        self.grey = info.pix_fmt in GREY_PIX_FMTS
        self._decided = self.grey  # else grey by content, decided in __iter__ (_verdict)
        if planes is None:
            planes = info.pix_fmt in PLANAR_DEFAULT_PIX_FMTS
        # PyAV opened the file (probe read its stream) and the planes split evenly.
        self.planar = (planes and info.pix_fmt in PLANAR_PIX_FMTS and info.time_base is not None
                       and info.width % 2 == 0 and info.height % 2 == 0)

    def _verdict(self, img) -> bool | None:
        """Grey (True), colour (False) or undecided (None: a blank neutral frame)."""
        if img.ndim == 2:
            return True
        img = np.asarray(img)
        g = img[..., 1]
        if not (np.array_equal(img[..., 0], g) and np.array_equal(g, img[..., 2])):
            return False
        return None if blank_frame(g) else True

    def _emit(self, img):
        """A decoded frame, 2-D (one channel) or (h, w, 3) BGR; read as grey later."""
        if img.ndim == 3 and img.shape[2] == 1:
            return img[:, :, 0]
        if img.ndim == 3 and img.shape[2] == 4:
            return img[:, :, :3]
        return img

    def _as_read(self, img):
        if not self.grey or img.ndim == 2:
            return img
        # a grey video: one channel, as a grey stream's decoding gives it
        return img.grey() if isinstance(img, PlanarFrame) else cv2.extractChannel(img, 1)

    def __iter__(self):
        if self.planar:
            raw = self._iter_planes()
        elif self.info.backend == "cv2":
            raw = self._iter_cv2()
        else:
            raw = self._iter_av()
        held, nbytes = [], 0
        for img in raw:
            if self._decided:
                yield self._as_read(img)
                continue
            verdict = self._verdict(img)
            held.append(img)
            nbytes += img.shape[0] * img.shape[1] * 3
            if verdict is None and nbytes < GREY_UNDECIDED_BYTES:
                continue
            self.grey, self._decided = verdict is True, True
            yield from map(self._as_read, held)
            held = []
        if held:  # blank neutral frames to the end: nothing says colour
            self.grey = self._decided = True
            yield from map(self._as_read, held)

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


    def _opencv_agrees(self, frame: PlanarFrame) -> bool:
        """Whether OpenCV decodes the video's first frame to ``frame``'s
        levels, whole (PyAV's swscale) and by window (the compiled
        arithmetic), to the bit: else the video is read through OpenCV (a
        build converting otherwise: another CPU's SIMD path, a colour matrix
        or range OpenCV reads from the stream)."""
        cap = _open_cv2(self.path)
        if cap is None:
            return False
        try:
            with quiet_native_stderr():
                ok, ref = cap.read()
        finally:
            cap.release()
        h, w = frame.shape[:2]
        win = frame.window(0, h, 0, w)  # (before the whole frame is kept: windows would be sliced from it)
        return bool(ok and ref is not None and ref.shape == frame.shape
                    and np.array_equal(win, ref) and np.array_equal(np.asarray(frame), ref))

    def _iter_planes(self):
        import av

        full_range = PLANAR_PIX_FMTS[self.info.pix_fmt]
        with quiet_native_stderr():
            c = av.open(str(self.path))
        first = True
        try:
            s = c.streams.video[0]
            for fr in c.decode(s):
                if fr.format.name != self.info.pix_fmt:  # the stream changed format: BGR whole
                    first = False
                    yield self._emit(fr.to_ndarray(format="bgr24"))
                    continue
                # the frame's colour matrix, as PyAV's and OpenCV's swscale read it
                matrix = SWS_MATRICES.get(getattr(fr, "colorspace", None), "bt601")
                frame = PlanarFrame(fr, full_range, matrix)
                if first:
                    if not self._opencv_agrees(PlanarFrame(fr, full_range, matrix)):
                        break
                first = False
                yield frame
        except av.error.FFmpegError as exc:
            raise TrackError(str(exc)) from None
        finally:
            c.close()
        if first:  # OpenCV's levels differ (or no frame): its own decoding throughout
            self.planar = False
            yield from (self._iter_cv2() if self.info.backend == "cv2" else self._iter_av())


class ThreadedFrames:
    """A :class:`FrameSource` decoded on a second thread into a bounded queue.

    OpenCV and PyAV release the GIL while decoding, so decoding overlaps the
    tracker's work.  Iterating yields frames; a decoding failure arrives as
    the exception, raised from the iterator (after the frames decoded
    before it).  :meth:`close` stops the thread.

    Frames cross in lists of up to ``CHUNK``: a queue hand-over (a lock, a
    condition's wake-up of the other thread) per frame cost ~12 us of CPU a
    frame more than one per 8 frames (``/tmp/speed14/qb.py``, speed14 in
    ``docs/measurements.md``); the same frames in the same order.
    """

    CHUNK = 8

    def __init__(self, source, maxsize: int):
        # About ``maxsize`` frames held: the queue's lists and the one the
        # decoding thread fills (lists of fewer frames when few fit: large frames).
        self.chunk = max(1, min(self.CHUNK, int(maxsize) // 4))
        self.q: queue.Queue = queue.Queue(maxsize=max(int(maxsize) // self.chunk, 2))
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, args=(source,), daemon=True)
        self._t.start()

    def _put(self, item) -> bool:
        while not self._stop.is_set():
            try:
                self.q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _run(self, source):
        chunk = []
        try:
            for img in source:
                chunk.append(img)
                if len(chunk) == self.chunk:
                    if not self._put(chunk):
                        return
                    chunk = []
            if chunk:
                self._put(chunk)
        except BaseException as exc:  # surfaced on the consumer's thread, after the frames before it
            if chunk:
                self.q.put(chunk)
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
            yield from item

    def close(self):
        self._stop.set()
        while self._t.is_alive():
            try:
                self.q.get_nowait()
            except queue.Empty:
                pass
            self._t.join(timeout=0.05)


__all__ = ["FrameSource", "PlanarFrame", "ThreadedFrames", "TrackError", "VideoInfo", "frame_times", "probe"]
