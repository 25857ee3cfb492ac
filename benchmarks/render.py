"""Rendering throughput against encoding the same frames, measured in one run.

Renders a 1280 x 640, 240 fps, 4 s shot with ``render_video`` (drawing, noise
and encoding, overlapped on two threads) and, in the same run, encodes the
identical precomputed frames with the same codec and nothing else.  Prints
frames per second of both and their ratio (target >= 0.8).

Usage: python benchmarks/render.py [--codec MJPG] [--codec FFV1] [--noise 5] [--seconds 4]
"""

import argparse
import tempfile
import time
from pathlib import Path

# This file is named after the package it measures: keep its own folder off
# the import path so that ``import render`` finds the package.

from cuespin.data_gen.sampler import make_scene, sample_shot
from cuespin.render import FrameRenderer, render_video
from cuespin.render.video import encode_frames


def bench(codec: str, noise: float, seconds: float, repeat: int) -> dict:
    shot, params = sample_shot(1, "case3")
    scene = make_scene(shot, params, fps=240.0,
                       render={"noise_sigma": noise, "codec": codec, "duration": seconds,
                               "gradient": 10.0})
    frames = list(FrameRenderer(scene).frames())
    n = len(frames)
    size = (scene.camera.width, scene.camera.height)
    best_enc = best_ren = float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeat):  # interleaved, best of N: the machine is shared
            t = time.perf_counter()
            encode_frames(iter(frames), Path(tmp) / "enc.avi", codec, 240.0, size)
            best_enc = min(best_enc, time.perf_counter() - t)
            t = time.perf_counter()
            render_video(scene, Path(tmp) / "ren.avi")
            best_ren = min(best_ren, time.perf_counter() - t)
    return {"codec": codec, "frames": n, "encode_fps": n / best_enc, "render_fps": n / best_ren,
            "ratio": best_enc / best_ren}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--codec", action="append", help="FourCC (repeatable); default MJPG and FFV1")
    ap.add_argument("--noise", type=float, default=5.0, help="noise sigma, grey levels")
    ap.add_argument("--seconds", type=float, default=4.0, help="video length, s")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each, best taken")
    args = ap.parse_args()
    print(f"{'codec':6} {'frames':>6} {'encode fps':>11} {'render fps':>11} {'ratio':>6}")
    for codec in args.codec or ["MJPG", "FFV1"]:
        r = bench(codec, args.noise, args.seconds, args.repeat)
        print(f"{r['codec']:6} {r['frames']:6d} {r['encode_fps']:11.1f} {r['render_fps']:11.1f} "
              f"{r['ratio']:6.2f}")


if __name__ == "__main__":
    main()
