"""Real files: H.264/MP4 through PyAV, variable frame rate, grey and colour frames."""

import json
import subprocess
import sys

import av
import numpy as np
import pytest

from cuespin.data_gen.sampler import make_scene, sample_shot
from cuespin.render import read_truth_csv, render_video, truth_path
from cuespin.render.timing import VFR_TIME_BASE, frame_times
from cuespin.render.video import H264_CRF, VideoError, encode_frames


def decode(path, fmt="gray"):
    """Every frame of a video as arrays, with its pts (s) relative to frame 0."""
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        frames, pts = [], []
        for fr in c.decode(s):
            frames.append(fr.to_ndarray(format=fmt))
            pts.append(fr.pts)
        tb = s.time_base
    t = np.array([float((p - pts[0]) * tb) for p in pts])
    return np.stack(frames), t, tb


def small_scene(fps=120.0, duration=0.4, **render):
    """A case-3 shot seen at 200 px/m (a 512 x 256 view), short and fast to write."""
    shot, params = sample_shot(4, "case3")
    settings = {"noise_sigma": 3.0, "codec": "H264", "duration": duration, "seed": 5, **render}
    return make_scene(shot, params, fps=fps, px_per_m=200.0, render=settings)


def test_h264_constant_rate_pts_and_sidecar(tmp_path):
    scene = small_scene()
    video = tmp_path / "shot.mp4"
    truth = render_video(scene, video)
    frames, t, tb = decode(video)
    assert len(frames) == len(truth.t) == 48
    assert frames.shape[1:] == (scene.camera.height, scene.camera.width)
    # Constant rate: k / fps exactly (the muxer's time base is a multiple of fps).
    assert np.array_equal(t, np.arange(48) / 120.0)
    side = read_truth_csv(truth_path(video))
    assert np.array_equal(side["t"], t)
    with av.open(str(video)) as c:
        s = c.streams.video[0]
        assert s.codec_context.name == "h264" and s.codec_context.pix_fmt == "yuv420p"
        assert s.average_rate == 120


@pytest.mark.parametrize("fps", [60.0, 480.0])
def test_vfr_pts_equal_truth_to_time_base(tmp_path, fps):
    scene = small_scene(fps=fps, duration=40 / fps, vfr_jitter=0.03)
    video = tmp_path / "vfr.mp4"
    truth = render_video(scene, video)
    _, t, tb = decode(video)
    side = read_truth_csv(truth_path(video))
    # The file keeps the writer's 1/90000 s clock; every frame's time equals
    # the sidecar's and the drawn time exactly (same ticks, same division).
    assert tb == VFR_TIME_BASE
    assert np.array_equal(t, side["t"]) and np.array_equal(t, truth.t)
    ratio = np.diff(t) * fps
    assert ratio.min() >= 0.97 - 1e-9 / fps and ratio.max() <= 1.03 + 1e-9 * fps
    assert ratio.std() > 0.01  # really variable: uniform +-3% has sd 1.7%
    # The frames' times depart from k / fps by more than a tick (CONVENTIONS.md's test).
    assert np.abs(t - np.arange(len(t)) / fps).max() > 2 * float(tb)


def test_frame_times_one_source():
    scene = small_scene(vfr_jitter=0.03)
    a, b = frame_times(scene, 30), frame_times(scene, 30)
    assert np.array_equal(a.t, b.t) and a.variable
    assert np.array_equal(a.t, a.pts / 90000)  # what float(pts * time_base) gives a reader
    assert not frame_times(small_scene(), 30).variable
    with pytest.raises(ValueError, match="render.vfr_jitter"):
        frame_times(small_scene(vfr_jitter=0.7), 30)


@pytest.mark.parametrize("colour", [False, True])
def test_grey_and_colour_frames_round_trip(tmp_path, colour):
    h, w = 64, 96
    base = np.zeros((h, w, 3), np.uint8)
    base[..., 0], base[..., 1], base[..., 2] = 40, 120, 200  # BGR felt-like blocks
    base[16:48, 24:72] = (200, 200, 40)
    frames = []
    for k in range(12):
        img = base.copy()
        img[20 + k:30 + k, 30:40] = 255
        frames.append(img if colour else img[..., 1].copy())
    video = tmp_path / "c.mp4"
    n = encode_frames(iter(frames), video, "H264", 30.0, (w, h), crf=12)
    assert n == 12
    got, t, _ = decode(video, "bgr24" if colour else "gray")
    assert np.array_equal(t, np.arange(12) / 30)
    err = np.abs(got.astype(float) - np.stack(frames).astype(float))
    # yuv420p halves the chroma's resolution: colour edges blur by a pixel;
    # measured mean error 0.59 grey levels (colour) and 0.008 (grey) at CRF 12.
    assert err.mean() < (1.5 if colour else 0.1)
    # AVI through OpenCV takes colour too.
    avi = tmp_path / "c.avi"
    assert encode_frames(iter(frames), avi, "MJPG", 30.0, (w, h)) == 12
    assert decode(avi, "bgr24" if colour else "gray")[0].shape[0] == 12


def test_crf_sets_the_size(tmp_path):
    sizes = {}
    for crf in (14, H264_CRF, 26):
        scene = small_scene(duration=0.25, crf=crf, noise_sigma=3.0)
        video = tmp_path / f"crf{crf}.mp4"
        render_video(scene, video)
        sizes[crf] = video.stat().st_size / 30
    # Lower CRF keeps more: at CRF 14 x264 keeps the sensor noise (measured
    # 10.8 kB per 512x256 frame), at 20 and above it smooths it away as a
    # phone's encoder does (0.24 kB at 20, 0.10 at 26; most of it the first frame).
    assert sizes[14] > 3 * sizes[H264_CRF] > 3 * sizes[26] * 0.9
    assert 50 < sizes[H264_CRF] < 5000


def test_vfr_needs_h264(tmp_path):
    scene = small_scene(codec="MJPG", vfr_jitter=0.03)
    with pytest.raises(VideoError, match="vfr_jitter"):
        render_video(scene, tmp_path / "v.avi")
    with pytest.raises(VideoError, match=r"\.mp4"):
        render_video(small_scene(), tmp_path / "v.avi")
    with pytest.raises(VideoError, match="render.crf"):
        render_video(small_scene(crf=80), tmp_path / "v.mp4")


def run(*args):
    return subprocess.run([sys.executable, "-m", "cuespin.pipeline.cli", *map(str, args)],
                          capture_output=True, text=True)


def test_cli_render_vfr_refused_one_line(tmp_path):
    from cuespin.pipeline.io import write_scene

    sf = tmp_path / "s.json"
    write_scene(sf, small_scene(codec="MJPG", vfr_jitter=0.03))
    res = run("render", sf, "-o", tmp_path / "v.avi")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "vfr_jitter" in res.stderr and "Traceback" not in res.stderr


@pytest.mark.slow  # renders a whole 1280 x 640 shot: 16 s
def test_generate_h264_dataset(tmp_path):
    res = run("generate", "--n", 1, "--seed", 3, "--out", tmp_path / "ds", "--preset", "case4",
              "--fps", 60, "--codec", "H264")
    assert res.returncode == 0, res.stderr
    names = sorted(p.name for p in (tmp_path / "ds").iterdir())
    assert names == ["shot_0000.json", "shot_0000.mp4", "shot_0000.truth.csv"]
    assert json.loads((tmp_path / "ds" / "shot_0000.json").read_text())["render"]["codec"] == "H264"
    frames, t, _ = decode(tmp_path / "ds" / "shot_0000.mp4")
    assert len(frames) == len(read_truth_csv(tmp_path / "ds" / "shot_0000.truth.csv")["t"])


def test_tracker_reads_the_vfr_times_the_renderer_wrote(tmp_path):
    from cuespin.track.video import track_video

    scene = small_scene(fps=120.0, duration=0.5, vfr_jitter=0.03)
    video = tmp_path / "vfr.mp4"
    truth = render_video(scene, video)
    tr = track_video(video, scene)
    # Equal to far below the file's 1/90000 s resolution (float rounding only).
    assert len(tr.t) == len(truth.t)
    assert np.abs(tr.t - truth.t).max() < 1e-12
