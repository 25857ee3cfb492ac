"""Tracker speed against decode-only, memory against length, accuracy against the bound.

speed:    per codec (MJPG, FFV1, mp4v, H.264 written with PyAV's libx264) a
          1280 x 640, 240 fps colour shot (a yellow ball on green felt, noise
          3 per channel) of 1000 and of 10000 frames; in one run on the same
          file, alternating, decoding every frame to BGR with cv2 and
          nothing else, and the full tracker; prints both throughputs and the
          median of the ratios (target >= 0.8), and the median ratio of
          their CPU times (process-wide, both threads: less noisy than wall
          time on a shared machine, and what a fully loaded one gives).
memory:   peak RSS of the tracker (in a fresh process) on a 1000-frame video
          and on a 10000-frame one (target: within 20 MB).
accuracy: centroid RMSE against the truth sidecar and the Cramer-Rao bound
          (from the rendered image's derivatives) per noise level, ball
          radius, blur, lighting gradient and codec, for the disc fit and for
          moments; and the RMS of the errors in the tracker's stated
          per-frame errors (target ~1 on lossless video).

colour:   per ball/felt colour pair, noise and codec: the colour tracker's
          RMSE against the colour Cramer-Rao bound (every channel), err/se, and
          the same frames' luma tracked grey-only, side by side.

Usage: python benchmarks/track.py [speed] [memory] [colour] [accuracy] [--quick] [--frames 1000 10000]
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2

from cuespin.data_gen.sampler import make_scene, sample_shot
from cuespin.physics import Shot
from cuespin.pipeline.measure import tracker_accuracy
from cuespin.track.synthetic import colour_frames, write_av
from cuespin.track.video import decode_seconds, track_video

# PyAV encoder, pixel format, options and file type per codec: what cameras
# and common tools write.
CODECS = {
    "MJPG": ("mjpeg", "yuvj420p", None, "avi", 8e5),  # bits per frame: 0.1 MB, as OpenCV writes
    "FFV1": ("ffv1", "bgr0", None, "avi", None),
    "mp4v": ("mpeg4", "yuv420p", None, "avi", 2e5),
    "H264": ("libx264", "yuv420p", {"crf": "18"}, "mp4", None),  # x264's default keyframe interval, 250
}


def scene_for(codec, seconds, fps=240.0, noise=5.0, px_per_m=500.0, blur=False, gradient=0.0,
              seed=1, t0=0.3):
    shot, params = sample_shot(seed, "case3")
    shot = Shot(shot.x0, shot.v0, shot.w0, t0=t0)
    return make_scene(shot, params, fps=fps, px_per_m=px_per_m,
                      exposure_s=(1.0 / fps if blur else 0.0),
                      render={"noise_sigma": noise, "codec": codec, "duration": seconds,
                              "gradient": gradient, "gradient_angle": 0.6, "seed": seed,
                              "felt_grey": 90.0, "ball_grey": 210.0})


def colour_video(tmp, codec, n_frames, fps=240.0):
    """A colour shot of ``n_frames`` written with PyAV; (path, scene)."""
    scene = scene_for(codec, n_frames / fps, fps=fps)
    enc, pix, opts, ext, rate = CODECS[codec]
    path = Path(tmp) / f"speed_{codec}_{n_frames}.{ext}"
    if not path.exists():
        write_av(colour_frames(scene, (40, 200, 220), (40, 110, 30), noise=3.0, seed=1, noise_bank=16),
                 path, enc, pix, fps, options=opts, bit_rate=rate and rate * fps)
    return path, scene


def decode_only(path) -> float:
    """Decode-only throughput (frames/s): every frame to BGR with cv2, as any
    OpenCV user decodes (:func:`cuespin.track.video.decode_seconds`)."""
    seconds, n = decode_seconds(path)
    return n / seconds


def speed(tmp, repeat, lengths):
    print("\nspeed: 1280x640 colour, 240 fps (median of alternating runs)")
    print(f"{'codec':6} {'frames':>6} {'decode fps':>11} {'track fps':>10} {'ratio':>6} {'cpu':>5}  ok")
    for n in lengths:
        for codec in CODECS:
            video, scene = colour_video(tmp, codec, n)
            decs, trks, ratios, cpus = [], [], [], []
            for _ in range(repeat):  # interleaved: the machine is shared
                c = time.process_time()
                d = decode_only(video)
                c_dec = time.process_time() - c
                t, c = time.perf_counter(), time.process_time()
                res = track_video(video, scene)
                k = res.n_frames / (time.perf_counter() - t)
                cpus.append(c_dec / (time.process_time() - c))
                decs.append(d)
                trks.append(k)
                ratios.append(k / d)
            print(f"{codec:6} {res.n_frames:6d} {statistics.median(decs):11.1f} "
                  f"{statistics.median(trks):10.1f} {statistics.median(ratios):6.2f} {statistics.median(cpus):5.2f}  "
                  f"{res.ok.sum()}/{res.n_frames}", flush=True)
            if n >= 5000:
                video.unlink()


_CHILD = """
import json, resource, sys
from cuespin.pipeline.io import read_scene
from cuespin.track.video import decode_seconds, track_video
scene = read_scene(sys.argv[2])
res = track_video(sys.argv[1], scene)
print(json.dumps({"frames": res.n_frames, "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def memory(tmp, lengths):
    from cuespin.pipeline.io import write_scene
    print("\nmemory: peak RSS of a fresh tracking process (MJPG, colour)")
    out = {}
    for n in lengths:
        video, scene = colour_video(tmp, "MJPG", n)
        sf = Path(tmp) / f"mem_{n}.json"
        write_scene(sf, scene)
        r = subprocess.run([sys.executable, "-c", _CHILD, str(video), str(sf)], capture_output=True,
                           text=True, check=True)
        out[n] = json.loads(r.stdout.strip().splitlines()[-1])
        print(f"{n:6d} frames: {out[n]['frames']:5d} tracked, peak RSS {out[n]['maxrss_mb']:.1f} MB")
    a, b = min(lengths), max(lengths)
    print(f"{b} frames add {out[b]['maxrss_mb'] - out[a]['maxrss_mb']:.1f} MB to {a} (target <= 20)")


def accuracy_row(tmp, label, scene, refine):
    acc = tracker_accuracy(scene, Path(tmp) / "acc.avi", refine, n_eval=10)
    res = acc.result
    print(f"{label:44} {refine:8} {acc.rmse:9.4f} {acc.crb:9.4f} {acc.ratio:6.2f} {acc.stated_z:7.2f}  "
          f"ok {res.ok.sum()}/{res.n_frames}")
    return acc.rmse, acc.crb


def accuracy(tmp, quick):
    print("\naccuracy: per-axis centroid RMSE (px) over moving frames vs Cramer-Rao bound")
    print("(err/se: RMS of the errors in the tracker's own stated errors; 1 when they are honest)")
    print(f"{'condition':44} {'refine':8} {'rmse':>9} {'bound':>9} {'ratio':>6} {'err/se':>7}")
    noises = (0.1, 0.3, 1.0, 5.0, 10.0)  # below ~0.5, 8-bit rounding is most of the noise
    radii = (8.0, 14.3, 20.0) if not quick else (14.3,)
    for codec in ("FFV1", "MJPG"):
        for noise in noises:
            for radius in radii:
                for blur, grad in ((False, 0.0), (True, 15.0)):
                    scene = scene_for(codec, 0.6, noise=noise, px_per_m=radius / 0.028575,
                                      blur=blur, gradient=grad)
                    label = f"{codec} sigma {noise:4.1f} r {radius:4.1f}px {'blur+grad' if blur else 'sharp'}"
                    for refine in (("fit", "moments") if codec == "FFV1" else ("fit",)):
                        accuracy_row(tmp, label, scene, refine)


# Ball and felt colours (BGR): the pairs, two under 25 grey levels apart.
PAIRS = {"yellow/grey": ((40, 200, 220), (170, 170, 170)),
         "red/blue": ((40, 40, 200), (150, 80, 40)),
         "red/green": ((40, 40, 200), (40, 110, 30)),
         "white/grey": ((230, 230, 230), (120, 120, 120)),
         "orange/red": ((30, 120, 240), (40, 40, 150))}


def colour_accuracy(tmp, pair, noise, codec="FFV1", fps=240.0, seed=1, grey=False, ramp=0.0):
    """RMSE, the colour Cramer-Rao bound and err/se on moving frames of one colour shot.

    With ``grey`` the same frames' luma is tracked instead (the grey-only
    tracker's view), against the same colour bound.
    """
    import numpy as np

    from cuespin.render import FrameRenderer
    from cuespin.track.bound import centroid_crb_colour

    ball, felt = PAIRS[pair]
    scene = scene_for(codec, 0.6, fps=fps, seed=seed)
    enc, pix, opts, ext, rate = CODECS[codec]
    path = Path(tmp) / f"acc.{ext}"
    frames = colour_frames(scene, ball, felt, noise=noise, seed=seed, ramp=ramp)
    if grey:
        w = np.array([0.114, 0.587, 0.299])
        frames = (np.clip(np.rint(f @ w), 0, 255).astype(np.uint8) for f in frames)
        pix = "gray" if codec == "FFV1" else pix
    write_av(frames, path, enc, pix, fps, options=opts, bit_rate=rate and rate * fps)
    res = track_video(path, scene)
    r = FrameRenderer(scene)
    truth = r.truth
    moving = np.flatnonzero(res.ok & (truth.t > scene.truth.t0 + 0.02))
    err = res.uv[moving] - truth.uv[moving]
    h, wd = scene.camera.height, scene.camera.width
    light = 1.0 + ramp * (np.arange(wd) / wd - 0.5)
    felt_img = np.asarray(felt, float)[None, None, :] * light[None, :, None] * np.ones((h, 1, 1))
    bounds = [centroid_crb_colour(r._uv_nodes[k], r.radius_px, ball, felt_img, noise**2 * np.eye(3), False)
              for k in moving[np.linspace(0, len(moving) - 1, 8).astype(int)]]
    z = err / res.stderr_px[moving]
    found = res.ok[truth.t > scene.truth.t0 + 0.02].mean()
    return (float(np.sqrt(np.mean(err**2))), float(np.sqrt(np.mean(np.square(bounds)))),
            float(np.sqrt(np.mean(z**2))), float(found))


def colour(tmp, quick):
    print("\ncolour: per-axis RMSE (px) on moving frames vs the colour Cramer-Rao bound (every channel)")
    print("grey: the same frames' luma tracked (grey-only), against the same colour bound")
    print(f"{'pair':12} {'codec':5} {'noise':>5} {'found':>6} {'rmse':>8} {'bound':>8} {'ratio':>6} "
          f"{'err/se':>6} | {'grey rmse':>9} {'ratio':>6} {'err/se':>6}")
    noises = (2.0, 8.0) if quick else (1.0, 2.0, 4.0, 8.0)
    for codec in ("FFV1", "MJPG"):
        for pair in PAIRS:
            for noise in noises:
                rm, b, z, f = colour_accuracy(tmp, pair, noise, codec)
                rg, _, zg, fg = colour_accuracy(tmp, pair, noise, codec, grey=True)
                print(f"{pair:12} {codec:5} {noise:5.1f} {f:6.3f} {rm:8.4f} {b:8.4f} {rm / b:6.2f} {z:6.2f} | "
                      f"{rg:9.4f} {rg / b:6.2f} {zg:6.2f}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("parts", nargs="*", default=["speed", "memory", "colour", "accuracy"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one radius in the accuracy table")
    ap.add_argument("--frames", type=int, nargs="+", default=[1000, 10000])
    args = ap.parse_args()
    cv2.setNumThreads(2)
    with tempfile.TemporaryDirectory() as tmp:
        if "speed" in args.parts:
            speed(tmp, args.repeat, args.frames)
        if "memory" in args.parts:
            memory(tmp, args.frames)
        if "colour" in args.parts:
            colour(tmp, args.quick)
        if "accuracy" in args.parts:
            accuracy(tmp, args.quick)


if __name__ == "__main__":
    main()
