"""The cue rules' decisions over generated cue scenes (issue 10; cue10 in docs/measurements.md).

    python benchmarks/cue_rules.py --seeds 100 101 --n 40 --json /tmp/cue_rules.json
    python benchmarks/cue_rules.py --summarize /tmp/cue_rules.json

Two rules tell the cue's motion from the ball's by the shape of what moved
(:func:`cuespin.track.video.cue_band`: a band narrower than
``STICK_WIDTH_RADII`` and longer than ``STICK_MOVED_RADII`` ball radii):
:func:`~cuespin.track.video.cue_moved` on a look-ahead's whole moved band (a
look-ahead where only the cue moved is not the ball's motion) and
:func:`~cuespin.track.background.stick_parts` on each moved part (a stick
beside the ball is left out of its model).  For every scene with a cue among
``sample_scenes(n, seed, realistic)`` (0.8 s, lossless: the renders
themselves), colour and grey: the tracker's own look-aheads (slid as
``track_video`` slides them), the frames before the strike (the ball at
rest, the cue approaching: cue-only) and the 41 frames up to where the ball
moved 0.5, 1 and 2 radii (its crescent beside the cue's tip).  Each moved
part is labelled by the truth: the ball's (within 1.5 r of its path over the
samples), the cue's (within 2 r of the shot line behind the ball) or other.
Printed: the moved bands' and parts' widths and lengths (in ball radii) per
label, and how often the rule fires on each at a grid of thresholds.
"""

from __future__ import annotations

import argparse
import json

import cv2
import numpy as np

import cuespin.track.background as bgm
from cuespin.data_gen.sampler import sample_scenes
from cuespin.render.draw import FrameRenderer
from cuespin.track.radius import RadiusMap
from cuespin.track.tracker import STICK_WIDTH_RADII
from cuespin.track.video import (LEARN_MOVED_AREA, LOOKAHEAD_BYTES, LOOKAHEAD_MIN_FRAMES, STICK_MOVED_RADII, cue_band,
                                 cue_moved, learn_model, search_mask)

_PARTS = []
_stick_parts = bgm.stick_parts


def _spy(xs, ys, strong, r, shape):
    """stick_parts, recording every part it judged (the same parts)."""
    out = _stick_parts(xs, ys, strong, r, shape)
    if strong.any():
        m = np.zeros(shape, np.uint8)
        m[ys[strong], xs[strong]] = 1
        d = max(3, int(round(bgm.PART_GAP_RADII * r)) | 1)
        n, lab = cv2.connectedComponents(cv2.dilate(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d, d))))
        part = np.where(strong, lab[ys, xs], 0)
        for i in range(1, n):
            on = part == i
            w, L = bgm.band_extent(xs[on], ys[on])
            _PARTS.append(dict(w=w / r, L=L / r, n=int(on.sum()), cu=float(xs[on].mean()),
                               cv=float(ys[on].mean()), removed=bool(out[on].any())))
    return out


class Frames:
    """A look-ahead's frames ``ks`` of ``fr``, each rendered when first read
    (learn_model reads its samples only), one fixed generator per frame."""

    def __init__(self, fr, ks, grey, cache):
        self.fr, self.ks, self.grey, self.cache = fr, list(ks), grey, cache

    def __len__(self):
        return len(self.ks)

    def __getitem__(self, i):
        k = self.ks[i]
        if k not in self.cache:
            self.cache[k] = self.fr.render(int(k), np.random.default_rng([k, 7]))
        f = self.cache[k]
        return cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) if self.grey else f


def _seg_dist(p, a, b):
    ab = b - a
    t = np.clip(np.dot(p - a, ab) / max(np.dot(ab, ab), 1e-12), 0, 1)
    return float(np.hypot(*(p - a - t * ab)))


def windows(fr, uv, k0, r, h, w):
    """(name, grey, frames) of the look-aheads judged in one scene."""
    N = fr.n_frames
    out = []
    for grey in (False, True):
        ahead = max(LOOKAHEAD_MIN_FRAMES, LOOKAHEAD_BYTES // (h * w * (1 if grey else 3)))
        lo = 0
        while True:
            out.append(("track_grey" if grey else "track_colour", grey, list(range(lo, min(lo + ahead, N)))))
            if lo + ahead >= N:
                break
            lo += ahead // 2
    if k0 >= 6:
        out += [("prestrike", False, list(range(k0))), ("prestrike_grey", True, list(range(k0)))]
    moved = np.hypot(*(uv - uv[0]).T)
    for frac in (0.5, 1.0, 2.0):
        after = np.flatnonzero((moved >= frac * r) & (np.arange(N) >= k0))
        if len(after):
            ks = list(range(max(0, int(after[0]) - 40), int(after[0]) + 1))
            out += [(f"strike{frac}", False, ks), (f"strike{frac}_grey", True, ks)]
    return out


def measure(seeds, n_per, path):
    bgm.stick_parts = _spy
    rows = []
    for seed in seeds:
        for si, scene in enumerate(sample_scenes(n_per, seed, look="realistic", codec="FFV1")):
            if not scene.render["cue"]:
                continue
            scene.render.update(max_duration=0.8)
            fr = FrameRenderer(scene)
            cam, R = scene.camera, scene.physics.R
            h, w = cam.height, cam.width
            x0 = np.asarray(scene.truth.x0[:2])
            r = R * cam.px_per_m(cam.to_pixels(np.array([x0]))[0])
            mask = search_mask(cam, scene.table, R, (h, w))
            radii = RadiusMap((h, w), r, cam, R, region=mask)
            uv, t = fr.truth.uvc, fr.truth.t
            k0 = int(np.searchsorted(t, scene.truth.t0))
            v0 = np.asarray(scene.truth.v0)
            d = v0 / np.hypot(*v0)
            cue_a, cue_b = cam.to_pixels(np.array([x0, x0 - 1.8 * d]))
            gaps = fr.cue_tip(t)
            cache = {}
            for name, grey, ks in windows(fr, uv, k0, r, h, w):
                _PARTS.clear()
                sk = [ks[i] for i in np.unique(np.linspace(0, len(ks) - 1, 9).round().astype(int))]
                _, bg = learn_model(Frames(fr, ks, grey, cache), radii, 9, mask, True)
                path = uv[sk]
                for p in _PARTS:
                    q = np.array([p["cu"], p["cv"]])
                    db = min(_seg_dist(q, path[i], path[i + 1]) for i in range(len(path) - 1))
                    p["label"] = "ball" if db < 1.5 * r else ("cue" if _seg_dist(q, cue_a, cue_b) < 2 * r else "other")
                fired = bool(cue_moved(bg, radii.r_min))
                rows.append(dict(seed=seed, shot=si, name=name, grey=grey, fps=cam.fps, size=[w, h], r=r,
                                 ball=scene.render["ball_name"], felt=scene.render["felt_name"],
                                 k=[ks[0], ks[-1]], k0=k0, ball_px=float(np.ptp(path, axis=0).max()),
                                 cue_m=float(np.ptp(gaps[sk])), polarity=int(bg.polarity),
                                 moved_px=int(bg.moved_px), band=[bg.moved_band[0] / r, bg.moved_band[1] / r],
                                 cue_moved=fired, saw=bool(bg.polarity) and not fired
                                 and bg.moved_px >= LEARN_MOVED_AREA * np.pi * radii.r_min**2,
                                 parts=list(_PARTS)))
            print(f"seed {seed} shot {si} {w}x{h} {cam.fps:.0f} fps r {r:.1f} px: {len(cache)} renders", flush=True)
            with open(path, "w") as f:
                json.dump(rows, f)
    bgm.stick_parts = _stick_parts


def summarize(path):
    rows = json.load(open(path))
    act = [r for r in rows if r["polarity"] != 0 and r["parts"]]

    def has_ball(r):
        return any(p["label"] == "ball" for p in r["parts"])

    cue = [r for r in act if not has_ball(r)]
    ball = [r for r in act if has_ball(r)]
    bparts = [p for r in rows for p in r["parts"] if p["label"] == "ball"]
    cparts = [p for r in ball for p in r["parts"] if p["label"] == "cue"]
    print(f"{len({(r['seed'], r['shot']) for r in rows})} cue scenes, {len(rows)} look-aheads; something moved in "
          f"{len(act)}: only the cue's parts {len(cue)} (the ball at rest in {sum(r['ball_px'] < 0.5 for r in cue)}), "
          f"the ball's among them {len(ball)}; ball parts {len(bparts)}, cue parts beside the ball {len(cparts)}")
    q = [0, 5, 25, 50, 75, 95, 100]
    for name, S in (("cue-only band", [r["band"] for r in cue]), ("ball's band", [r["band"] for r in ball]),
                    ("ball part", [(p["w"], p["L"]) for p in bparts]),
                    ("cue part by the ball", [(p["w"], p["L"]) for p in cparts])):
        a = np.array(S)
        print(f"{name:21} width p{q} {np.percentile(a[:, 0], q).round(2)}  length {np.percentile(a[:, 1], q).round(2)}")
        narrow = a[a[:, 0] < STICK_WIDTH_RADII, 1]
        long = a[a[:, 1] > STICK_MOVED_RADII, 0]
        print(f"{'':21} narrower than {STICK_WIDTH_RADII} r: {len(narrow)}, longest {narrow.max(initial=0):.2f}; "
              f"longer than {STICK_MOVED_RADII} r: {len(long)}, narrowest {long.min(initial=np.inf):.2f}")
    print("fires (width < W r and length > L r): cue-only bands | ball's bands | ball parts | cue parts by the ball")
    for W in (0.9, 1.0, 1.1, 1.2, 1.3):
        for L in (2.0, 2.5, 3.0, 3.5):
            def f(w, length):
                return w < W and length > L
            print(f"  W {W:.1f} L {L:.1f}: {sum(f(*r['band']) for r in cue):3d}/{len(cue)} | "
                  f"{sum(f(*r['band']) for r in ball):3d}/{len(ball)} | {sum(f(p['w'], p['L']) for p in bparts):3d}/"
                  f"{len(bparts)} | {sum(f(p['w'], p['L']) for p in cparts):3d}/{len(cparts)}")
    # The rule as it stands (the JSON's own decisions were the rule's when measured).
    def left_out(r):
        stick = [cue_band((p["w"], p["L"]), 1.0) for p in r["parts"]]
        return [s and not all(stick) for s in stick]

    print(f"now (width < {STICK_WIDTH_RADII} r, length > {STICK_MOVED_RADII} r): cue_moved fires on "
          f"{sum(cue_band(r['band'], 1.0) for r in cue)}/{len(cue)} cue-only, "
          f"{sum(cue_band(r['band'], 1.0) for r in ball)}/{len(ball)} with the ball; stick_parts leaves out "
          f"{sum(o for r in rows for p, o in zip(r['parts'], left_out(r)) if p['label'] == 'ball')} ball parts, "
          f"{sum(o for r in ball for p, o in zip(r['parts'], left_out(r)) if p['label'] == 'cue')} cue parts by the ball")

def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[100, 101])
    p.add_argument("--n", type=int, default=40, help="scenes sampled per seed (about half have a cue)")
    p.add_argument("--json", default="cue_rules.json")
    p.add_argument("--summarize", default=None, help="only print the summary of a JSON written before")
    a = p.parse_args(argv)
    if not a.summarize:
        measure(a.seeds, a.n, a.json)
    summarize(a.summarize or a.json)


if __name__ == "__main__":
    main()
