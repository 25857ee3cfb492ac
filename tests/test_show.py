"""cuespin show and recover --plot: a picture (and a video) of one shot, from real files."""

import subprocess
import sys

import numpy as np
import pytest

import cuespin
from cuespin.physics.motion import BallParams, Shot


@pytest.fixture(scope="module")
def shot_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("show")
    scene = cuespin.make_scene(Shot((0.5, 0.4), (1.0, 0.2), (20.0, -30.0), 0.1), BallParams(mu_s=0.2, mu_r=0.01),
                               fps=120.0, px_per_m=250.0,
                               render={"noise_sigma": 2.0, "codec": "FFV1", "max_duration": 0.8, "seed": 3})
    cuespin.write_scene(d / "s.json", scene)
    cuespin.render_scene(scene, d / "v.avi")
    return d, scene


def cli(*args):
    return subprocess.run([sys.executable, "-m", "cuespin.pipeline.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=300)


def test_show_writes_picture_and_overlay_video(shot_files, tmp_path):
    import av

    d, scene = shot_files
    png, mp4 = tmp_path / "shot.png", tmp_path / "shot.mp4"
    res = cli("show", d / "v.avi", "--scene", d / "s.json", "-o", png, "--video", mp4)
    assert res.returncode == 0, res.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    with av.open(str(mp4)) as c:
        frames = sum(1 for _ in c.decode(video=0))
    assert frames == 97  # every frame of the 0.8 s, 120 fps video


def test_residuals_of_the_right_answer_are_at_the_stated_errors(shot_files):
    """The picture's lower panels: the MLE's own answer leaves residuals of about
    one stated error (the tracker's errors are honest on lossless video, README)."""
    from cuespin.pipeline.show import residuals

    d, scene = shot_files
    result, tr = cuespin.recover_video(d / "v.avi", scene, return_track=True)
    assert result["methods"]["mle"]["status"] == "ok"
    t, r = residuals(result, tr, scene)["mle"]
    far = np.abs(t - result["methods"]["mle"]["t0"]) > 2 / scene.camera.fps  # the strike's frames are left out
    rms = float(np.sqrt(np.mean(r[far] ** 2)))
    assert 0.5 < rms < 2.0, rms
    # The truth's path, drawn the same way, sits within the same band.
    truth = {"mle": dict(result["methods"]["mle"], x0=list(scene.truth.x0), v0=list(scene.truth.v0),
                         w0=list(scene.truth.w0), t0=scene.truth.t0)}
    _, rt = residuals({"methods": truth, "track": result["track"]}, tr, scene)["mle"]
    assert float(np.sqrt(np.mean(rt[far] ** 2))) < 2.0


@pytest.mark.slow
def test_recover_plot(shot_files, tmp_path):
    d, _ = shot_files
    png = tmp_path / "p.png"
    res = cli("recover", d / "v.avi", "--scene", d / "s.json", "--plot", png)
    assert res.returncode == 0, res.stderr
    assert png.stat().st_size > 20_000 and "t2 (s)" in res.stdout and "predicted" in res.stdout


def test_show_bad_output_one_line(shot_files, tmp_path):
    d, _ = shot_files
    bad = cli("show", d / "v.avi", "--scene", d / "s.json", "-o", tmp_path / "nope" / "p.png")
    assert bad.returncode == 2 and "output folder does not exist" in bad.stderr
    assert "Traceback" not in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
