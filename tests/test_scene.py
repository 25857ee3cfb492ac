"""Scene files: parsing, validation with one line naming the key, round trip."""

import json

import numpy as np
import pytest

from cuespin.data_gen.sampler import sample_scene
from cuespin.physics.scene import SceneError, default_camera, parse_scene, scene_to_dict

CONVENTIONS_EXAMPLE = {
    "schema": 1,
    "physics": {"R": 0.028575, "mu_s": 0.2, "mu_r": 0.01, "g": 9.81},
    "table": {"length": 2.54, "width": 1.27},
    "camera": {"fps": 240.0, "width": 1280, "height": 640,
               "homography": [[500, 0, 5], [0, -500, 635], [0, 0, 1]], "exposure_s": 0.0},
    "render": {"anything": "the renderer's"},
    "truth": {"x0": [0.6, 0.5], "v0": [1.2, 0.3], "w0": [5.0, -20.0], "t0": 0.25},
    "unknown_key": "ignored",
}


def test_conventions_example_parses():
    s = parse_scene(CONVENTIONS_EXAMPLE)
    assert s.camera.fps == 240.0 and s.camera.width == 1280
    assert s.truth.v0 == (1.2, 0.3) and s.truth.t0 == 0.25
    np.testing.assert_allclose(s.camera.to_pixels([[0.6, 0.5]]), [[305.0, 385.0]])
    np.testing.assert_allclose(s.camera.to_table(s.camera.to_pixels([[0.6, 0.5]])), [[0.6, 0.5]])
    assert s.camera.px_per_m([1.0, 0.5]) == pytest.approx(500.0)
    # The default camera is the conventions' example.
    assert default_camera().homography == s.camera.homography
    assert (default_camera().width, default_camera().height) == (1280, 640)


def test_only_physics_and_camera_required():
    s = parse_scene({"physics": {}, "camera": CONVENTIONS_EXAMPLE["camera"]})
    assert s.truth is None and s.physics.mu_s == 0.2 and s.table.length == 2.54


def test_round_trip():
    scene = sample_scene(3)
    again = parse_scene(json.loads(json.dumps(scene_to_dict(scene))))
    assert again == scene


def broken(path, value):
    d = json.loads(json.dumps(CONVENTIONS_EXAMPLE))
    *head, last = path.split(".")
    node = d
    for k in head:
        node = node[k]
    if value is KeyError:
        del node[last]
    else:
        node[last] = value
    return d


@pytest.mark.parametrize("path,value,expect", [
    ("physics", KeyError, "physics: required key is missing"),
    ("camera", KeyError, "camera: required key is missing"),
    ("camera.fps", KeyError, "camera.fps: required key is missing"),
    ("camera.homography", [[1, 0], [0, 1]], "camera.homography: expected shape [3, 3]"),
    ("camera.homography", [[1, 0, 0], [2, 0, 0], [0, 0, 1]], "camera.homography: matrix is singular"),
    ("camera.fps", 0, "camera.fps: must be > 0"),
    ("camera.fps", "fast", "camera.fps: expected a number"),
    ("physics.R", 0.0, "physics.R: must be > 0"),
    ("physics.mu_s", -0.1, "physics.mu_s: must be > 0"),
    ("physics.mu_r", -0.01, "physics.mu_r: must be >= 0"),
    ("physics.g", 0, "physics.g: must be > 0"),
    ("physics.g", float("nan"), "physics.g: must be finite"),
    ("truth.v0", [1.0], "truth.v0: expected shape [2]"),
    ("truth.w0", [1.0, float("inf")], "truth.w0: must be finite"),
    ("truth.t0", KeyError, "truth.t0: required key is missing"),
    ("schema", 2, "schema: this program reads schema 1"),
])
def test_invalid_scene_names_the_key(path, value, expect):
    with pytest.raises(SceneError) as err:
        parse_scene(broken(path, value))
    msg = str(err.value)
    assert msg.startswith(expect) and "\n" not in msg


def test_mu_r_zero_is_allowed():
    assert parse_scene(broken("physics.mu_r", 0.0)).physics.mu_r == 0.0


def test_defaults_said_on_stderr_and_size_from_video(tmp_path, capsys):
    """Item 7: physics values left out are said in one line; the frame size comes
    from the video when the scene leaves it out (a real rendered file, tracked)."""
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene
    from cuespin.physics.motion import BallParams, Shot
    from cuespin.pipeline.io import read_scene
    from cuespin.render import render_video
    from cuespin.track.video import track_video

    scene = make_scene(Shot(x0=(0.3, 0.3), v0=(0.5, 0.1), w0=(0.0, 0.0), t0=0.02), BallParams(),
                       fps=60.0, px_per_m=100.0,
                       render={"noise_sigma": 1.0, "codec": "FFV1", "duration": 0.3, "seed": 1})
    video = tmp_path / "v.avi"
    render_video(scene, video)
    d = scene_to_dict(scene)
    del d["camera"]["width"], d["camera"]["height"], d["physics"]["R"], d["physics"]["mu_r"]
    (tmp_path / "s.json").write_text(json.dumps(d))
    capsys.readouterr()
    read = read_scene(tmp_path / "s.json")
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "physics.R = 0.028575" in err and "physics.mu_r = 0.01" in err
    assert "mu_s" not in err
    assert read.camera.width is None
    res = track_video(video, read)
    assert res.ok.sum() > 10
    full = track_video(video, scene)
    np.testing.assert_allclose(res.xy[res.ok], full.xy[full.ok], atol=1e-12)
    # A size the scene states is still checked against the video.
    from cuespin.track.video import TrackError
    with pytest.raises(TrackError):
        track_video(video, replace(read, camera=read.camera.with_size(640, 480)))
