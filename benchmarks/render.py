"""Rendering throughput against encoding the same frames, measured in one run.

Renders a 240 fps, 4 s shot with ``render_video`` (drawing, noise and
encoding, overlapped on two threads) and, in the same run, encodes the
identical precomputed frames with the same codec and nothing else.  Prints
frames per second of both and their ratio (target >= 0.8), the median of
``--repeat`` alternating runs, and the median ratio of their CPU times
(process-wide: drawing and encoding threads; less noisy on a shared machine).  ``--look plain`` is the grey 1280 x 640 view;
``--look realistic`` a colour 1280 x 720 view with rails, two resting
balls, a highlight, dot markings and the cue.

``--offsets`` instead measures how far the intensity-weighted centroid of a
shaded ball's image lies from its centre, for a few looks (noise-free).

Usage: python benchmarks/render.py [--look realistic] [--codec MJPG] [--codec FFV1] [--codec H264] [--noise 5]
       python benchmarks/render.py --offsets
       python benchmarks/render.py --setup --look realistic --seconds 1.5 --repeat 3
"""

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from cuespin.data_gen.sampler import framed_camera, make_scene, realistic_look, sample_shot
from cuespin.physics.scene import Scene, Table, pinhole_camera
from cuespin.render import FrameRenderer, draw, render_video
from cuespin.render.video import encode_frames, video_suffix


def realistic_scene(shot, params, fps: float, render: dict, size=(1280, 720), exposure_s=0.0,
                    seed: int = 4, camera: str = "topdown") -> Scene:
    """A realistic-look scene for ``shot`` with ``render`` overriding the sampled look;
    ``camera="tilted"``: 2 m up, 10 deg tilt, k1 -0.2."""
    rng = np.random.default_rng(seed)
    table = Table()
    if camera == "tilted":
        cam = pinhole_camera(table, height_m=2.0, tilt_deg=10.0, size=size, k1=-0.2, fps=fps,
                             exposure_s=exposure_s)
    else:
        cam = framed_camera(rng, fps, table, exposure_s, size=size)
    look = realistic_look(rng, shot, params, table, fps)
    look.update(render)
    return Scene(physics=params, camera=cam, table=table, render=look, truth=shot)


def bench_scene(look: str, noise: float, seconds: float, camera: str = "topdown", **render):
    """The benchmark's shot (case 3, 240 fps) in the plain look (a felt
    gradient) or the realistic one (a highlight, dots, a cue, two other
    balls), ``render`` added to its render block."""
    shot, params = sample_shot(1, "case3")
    render.update(noise_sigma=noise, duration=seconds)
    if look == "plain":
        render["gradient"] = 10.0
        return make_scene(shot, params, fps=240.0, render=render)
    render.update(specular=0.5, markings="dots", cue=True,
                  balls=[{"x": 0.4, "y": 0.3, "colour": [45, 40, 200]},
                         {"x": 2.2, "y": 1.0, "colour": [30, 205, 240]}])
    return realistic_scene(shot, params, 240.0, render, camera=camera)


def bench(codec: str, look: str, noise: float, seconds: float, repeat: int,
          camera: str = "topdown", law: str = "byte") -> dict:
    scene = bench_scene(look, noise, seconds, camera, codec=codec)
    draw.NOISE_LAW = law
    frames = list(FrameRenderer(scene).frames())
    n = len(frames)
    size = (scene.camera.width, scene.camera.height)
    enc, ren, cpu, two = [], [], [], []
    ext = video_suffix(codec)                       # .mp4 for H264 (PyAV), else .avi
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeat):  # alternating, median of N: the machine is shared
            t, c = time.perf_counter(), time.process_time()
            encode_frames(iter(frames), Path(tmp) / f"enc{ext}", codec, 240.0, size)
            enc.append(time.perf_counter() - t)
            c_enc = time.process_time() - c
            t, c = time.perf_counter(), time.process_time()
            render_video(scene, Path(tmp) / f"ren{ext}")
            ren.append(time.perf_counter() - t)
            c_ren = time.process_time() - c
            cpu.append(c_enc / c_ren)
            # render_video draws and encodes on two threads: on two free cores
            # its throughput is set by the slower, drawing (its CPU less the
            # encoding's) or encoding.
            two.append(min(1.0, c_enc / max(c_ren - c_enc, 1e-9)))
    ratios = [e / r for e, r in zip(enc, ren)]
    return {"codec": codec, "look": look, "frames": n, "encode_fps": n / statistics.median(enc),
            "render_fps": n / statistics.median(ren), "ratio": statistics.median(ratios),
            "ratios": ratios, "cpu_ratio": statistics.median(cpu), "two_core": statistics.median(two)}


def setup_cost(look: str, noise: float, seconds: float, repeat: int, camera: str = "topdown") -> dict:
    """CPU (s) of the renderer's set-up (``FrameRenderer(scene)``: static layer,
    orientation) and of drawing the shot's frames without encoding, per run,
    after one warm-up render (noise tables, compiled kernels, imports)."""
    scene = bench_scene(look, noise, seconds, camera)
    for _ in FrameRenderer(scene).frames():
        pass
    setup, frames = [], []
    for _ in range(repeat):
        c = time.process_time()
        r = FrameRenderer(scene)
        c1 = time.process_time()
        for _ in r.frames():
            pass
        setup.append(c1 - c)
        frames.append(time.process_time() - c1)
    return {"frames": r.n_frames, "setup": setup, "draw": frames}


OFFSET_LOOKS = {
    "matte, overhead light": {"ambient": 0.35, "light_elevation": 1.5, "specular": 0.0},
    "matte, light at 60 deg": {"ambient": 0.35, "light_elevation": 1.05, "specular": 0.0},
    "matte, light at 50 deg, ambient 0.2": {"ambient": 0.2, "light_elevation": 0.87, "specular": 0.0},
    "highlight 0.5, light at 60 deg": {"ambient": 0.35, "light_elevation": 1.05, "specular": 0.5},
    "highlight 0.7, light at 50 deg": {"ambient": 0.3, "light_elevation": 0.87, "specular": 0.7},
}


def offsets() -> None:
    """Intensity-weighted centroid minus the true centre (px), per look and ball/felt pair."""
    shot, params = sample_shot(1, "case3")
    print("light azimuth 0 (from +x, i.e. +u in the image); psf 0.7 px; 1280x720, "
          f"radius {params.R:.4f} m; centroid of sum over channels of |frame - felt|")
    print(f"{'look':40} {'ball/felt':14} {'radius px':>9} {'du px':>7} {'dv px':>7}")
    for name, over in OFFSET_LOOKS.items():
        for ball, felt in (("white", "green"), ("red", "green"), ("yellow", "blue")):
            from cuespin.render.look import BALL_COLOURS, FELT_COLOURS
            render = dict(over, light_azimuth=0.0, psf_sigma=0.7, texture=0.0, ramp=0.0,
                          noise_sigma=0.0, markings="none", cue=False, balls=[],
                          ball_colour=list(BALL_COLOURS[ball]), felt_colour=list(FELT_COLOURS[felt]),
                          duration=0.05)
            scene = realistic_scene(shot, params, 240.0, render)
            r = FrameRenderer(scene)
            d, u0, v0 = r._ball_delta(0)
            m = np.abs(d).sum(-1)
            vv, uu = np.mgrid[0:m.shape[0], 0:m.shape[1]]
            c = np.array([(m * uu).sum(), (m * vv).sum()]) / m.sum() + [u0, v0]
            off = c - r.truth.uvc[0]
            print(f"{name:40} {ball + '/' + felt:14} {r.radius_px:9.2f} {off[0]:7.3f} {off[1]:7.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--codec", action="append", help="FourCC or H264 (repeatable); default MJPG, FFV1, H264")
    ap.add_argument("--look", choices=("plain", "realistic"), action="append",
                    help="look (repeatable); default both")
    ap.add_argument("--noise", type=float, default=5.0, help="noise sigma, grey levels")
    ap.add_argument("--seconds", type=float, default=4.0, help="video length, s")
    ap.add_argument("--repeat", type=int, default=3, help="alternating runs of each, median taken")
    ap.add_argument("--camera", choices=("topdown", "tilted"), default="topdown",
                    help="realistic look's camera (tilted: 2 m, 10 deg, k1 -0.2)")
    ap.add_argument("--offsets", action="store_true", help="measure shaded-ball centroid offsets")
    ap.add_argument("--setup", action="store_true",
                    help="CPU of the renderer's set-up and of drawing the frames (no encoding), --repeat runs")
    ap.add_argument("--noise-law", choices=("byte", "alias"), action="append",
                    help="realistic look's noise (render.draw.NOISE_LAW; repeatable); default byte")
    args = ap.parse_args()
    if args.offsets:
        offsets()
        return
    if args.setup:
        for look in args.look or ["plain", "realistic"]:
            r = setup_cost(look, args.noise, args.seconds, args.repeat, args.camera)
            print(f"{look:9} frames {r['frames']}: set-up CPU min {min(r['setup']) * 1e3:.0f} ms, median "
                  f"{statistics.median(r['setup']) * 1e3:.0f} ms; drawing CPU median "
                  f"{statistics.median(r['draw']) / r['frames'] * 1e3:.2f} ms a frame", flush=True)
        return
    print(f"camera {args.camera}")
    print("ratio: wall-clock; cpu: encoding's CPU / render_video's (which encodes too, so < 1 always); "
          "2core: min(1, encoding's CPU / drawing's), the wall ratio on two free cores")
    print(f"{'look':9} {'codec':6} {'law':5} {'frames':>6} {'encode fps':>11} {'render fps':>11} {'ratio':>6} "
          f"{'cpu':>5} {'2core':>5}  runs")
    for look in args.look or ["plain", "realistic"]:
        for codec in args.codec or ["MJPG", "FFV1", "H264"]:
            for law in args.noise_law or ["byte"]:
                r = bench(codec, look, args.noise, args.seconds, args.repeat, args.camera, law)
                runs = " ".join(f"{x:.2f}" for x in r["ratios"])
                print(f"{r['look']:9} {r['codec']:6} {law:5} {r['frames']:6d} {r['encode_fps']:11.1f} "
                      f"{r['render_fps']:11.1f} {r['ratio']:6.2f} {r['cpu_ratio']:5.2f} {r['two_core']:5.2f}  "
                      f"{runs}", flush=True)


if __name__ == "__main__":
    main()
