#!/usr/bin/env python3
"""Offline probe: does a moving pixel look like the background it covers?

For each frame t and each offset k, OpenCV DIS flow from t to t+k is
computed at 1/S of the frame size; inside the moving mask (dilated by 2 px)
the flow is replaced by a harmonic fill from the static pixels around it
(Jacobi iterations of a 3 × 3 mean), which follows the background's motion
under the object. Frame t+k is warped back along that flow. A moving pixel
whose warped location is static in the mask of t+k is tested against it:

- `shadow`: every colour ratio I_t / I_{t+k} in (0.2, 0.9) and their
  spread (max / min) below 1.35: the same surface, darker;
- `agree`: every ratio within 0.9–1.1: the same surface, as bright;
- `either`: one or the other.

Where the warped background is textured (grey standard deviation over
7 × 7 above 0.02) the two 7 × 7 grey patches must also correlate (NCC >
0.5). Pixels that pass in the first valid offset leave the mask; J before
and after is printed per sequence, against the DAVIS annotations.

Usage: background_probe.py PRED_ROOT DAVIS_ROOT SEQ[,SEQ...] [VIS_PREFIX]
PRED_ROOT/<seq>/masks/<frame>.jpg.png are keep-masks (255 keep, 0 moving),
as the `davis` example writes them (`OUT=…`); DAVIS_ROOT holds
JPEGImages/480p and Annotations/480p. Environment: MODE (shadow), S (4),
KS (offsets, 4,-4,8,-8,12,-12). Needs numpy and opencv-python-headless.
"""
import os
import sys

import cv2
import numpy as np

MODE = os.environ.get("MODE", "shadow")
S = int(os.environ.get("S", "4"))
KS = [int(k) for k in os.environ.get("KS", "4,-4,8,-8,12,-12").split(",")]


def harmonic_fill(flow, hole, iters=150):
    out = flow.copy()
    known = ~hole
    for c in range(2):
        out[..., c][hole] = out[..., c][known].mean() if known.any() else 0.0
    for _ in range(iters):
        avg = cv2.blur(out, (3, 3), borderType=cv2.BORDER_REPLICATE)
        out[hole] = avg[hole]
    return out


def passes(a, b):
    r = (a + 0.01) / (b + 0.01)
    rmax, rmin = r.max(-1), r.min(-1)
    shadow = (rmax < 0.9) & (rmin > 0.2) & (rmax / np.maximum(rmin, 1e-3) < 1.35)
    agree = (rmax < 1.1) & (rmin > 0.9)
    ratio = {"shadow": shadow, "agree": agree}.get(MODE, shadow | agree)
    ga = cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)
    gb = cv2.cvtColor(b, cv2.COLOR_BGR2GRAY)
    k = (7, 7)
    ma, mb = cv2.blur(ga, k), cv2.blur(gb, k)
    va = cv2.blur(ga * ga, k) - ma * ma
    vb = cv2.blur(gb * gb, k) - mb * mb
    cab = cv2.blur(ga * gb, k) - ma * mb
    ncc = cab / np.sqrt(np.maximum(va * vb, 1e-12))
    return ratio & np.where(vb > 0.02**2, ncc > 0.5, True)


def jaccard(p, g):
    u = (p | g).sum()
    return 1.0 if u == 0 else (p & g).sum() / u


def main():
    pred_root, davis, seqs = sys.argv[1], sys.argv[2], sys.argv[3].split(",")
    vis = sys.argv[4] if len(sys.argv) > 4 else None
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    before, after = [], []
    for s in seqs:
        names = sorted(os.listdir(f"{pred_root}/{s}/masks"))
        ims = [cv2.imread(f"{davis}/JPEGImages/480p/{s}/{n[:-4]}") for n in names]
        H, W = ims[0].shape[:2]
        h, w = H // S, W // S
        small = [cv2.resize(i, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255 for i in ims]
        grey = [cv2.cvtColor((x * 255).astype(np.uint8), cv2.COLOR_BGR2GRAY) for x in small]
        masks = [cv2.imread(f"{pred_root}/{s}/masks/{n}", 0) < 128 for n in names]
        msmall = [cv2.resize(m.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0 for m in masks]
        gts = [cv2.imread(f"{davis}/Annotations/480p/{s}/{n[:-8]}.png", 0) > 127 for n in names]
        xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        jb, ja = [], []
        for t, m in enumerate(msmall):
            drop = np.zeros((h, w), bool)
            decided = np.zeros((h, w), bool)
            hole = cv2.dilate(m.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
            for k in KS:
                u = t + k
                if not m.any() or u < 0 or u >= len(ims):
                    continue
                fb = harmonic_fill(dis.calc(grey[t], grey[u], None), hole)
                mx, my = xs + fb[..., 0], ys + fb[..., 1]
                warped = cv2.remap(small[u], mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1)
                mu = cv2.remap(msmall[u].astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1)
                valid = m & ~decided & (mu < 0.01) & (warped.min(-1) >= 0)
                if valid.any():
                    drop |= valid & passes(small[t], np.maximum(warped, 0))
                    decided |= valid
            full = cv2.resize(drop.astype(np.uint8), (W, H), interpolation=cv2.INTER_NEAREST) > 0
            kept = masks[t] & ~full
            jb.append(jaccard(masks[t], gts[t]))
            ja.append(jaccard(kept, gts[t]))
            if vis and t % 10 == 0:
                o = ims[t].astype(np.float32)
                o[kept] = o[kept] * 0.4 + np.array([0, 255, 0]) * 0.6
                o[full] = o[full] * 0.4 + np.array([255, 0, 255]) * 0.6
                cv2.imwrite(f"{vis}_{s}_{t:03d}.png", o.astype(np.uint8))
        print(f"{s:15s} J {np.mean(jb):.3f} -> {np.mean(ja):.3f}", flush=True)
        before.append(np.mean(jb))
        after.append(np.mean(ja))
    print(f"mean J {np.mean(before):.3f} -> {np.mean(after):.3f}")


if __name__ == "__main__":
    main()
