#!/usr/bin/env python3
"""Measurement (not part of romosplat): the inside-outside maps of
Papazoglou & Ferrari, "Fast object segmentation in unconstrained video"
(ICCV 2013), on DAVIS-2016 at RoMo's working grid, scored against the
annotation.

Motion boundaries from OpenCV's DIS flow (MEDIUM, frames at twice the
256 x 144 grid, flow averaged down to it): 1 - exp(-lambda |grad f|) > 0.5.
(The paper's flow-direction term only scales boundaries below 0.5, so it
cannot add one at this threshold and is left out.) A pixel is inside when
more than 4 of its 8 rays (axes and diagonals) cross an odd number of
boundaries.

    pip install numpy opencv-python-headless
    python3 scripts/inside_outside_probe.py blackswan,camel,goat 2 [DAVIS_DIR]

Prints J, precision and recall of the inside map per sequence.
"""
import glob
import sys

import cv2
import numpy as np

W, H = 256, 144
DIRECTIONS = [(0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)]


def shifted(a, dy, dx):
    """out[y, x] = a[y + dy, x + dx], zero outside."""
    h, w = a.shape
    out = np.zeros_like(a)
    ys, yd = (slice(dy, h), slice(0, h - dy)) if dy >= 0 else (slice(0, h + dy), slice(-dy, h))
    xs, xd = (slice(dx, w), slice(0, w - dx)) if dx >= 0 else (slice(0, w + dx), slice(-dx, w))
    out[yd, xd] = a[ys, xs]
    return out


def inside(boundary):
    """Majority of 8 rays with an odd number of boundary crossings."""
    h, w = boundary.shape
    votes = np.zeros((h, w), np.int32)
    for dy, dx in DIRECTIONS:
        # A crossing starts where the ray enters a run of boundary pixels.
        entry = (boundary & ~shifted(boundary, -dy, -dx)).astype(np.int32)
        count = np.zeros((h, w), np.int32)
        for k in range(1, max(h, w)):
            if (dy and k >= h) or (dx and k >= w):
                break
            count += shifted(entry, k * dy, k * dx)
        votes += count % 2
    return votes > 4


def boundaries(flow, lam):
    gu = np.gradient(flow[..., 0])
    gv = np.gradient(flow[..., 1])
    grad = np.sqrt(gu[0] ** 2 + gu[1] ** 2 + gv[0] ** 2 + gv[1] ** 2)
    return 1.0 - np.exp(-lam * grad) > 0.5


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    seqs, lam = sys.argv[1].split(","), float(sys.argv[2])
    root = sys.argv[3] if len(sys.argv) > 3 else "../shared/data/davis2016"
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    for s in seqs:
        files = sorted(glob.glob(f"{root}/JPEGImages/480p/{s}/*.jpg"))
        if len(files) < 2:
            sys.exit(f"{root}/JPEGImages/480p/{s}: fewer than 2 frames")
        grey = [
            cv2.cvtColor(cv2.resize(cv2.imread(f), (2 * W, 2 * H), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2GRAY)
            for f in files
        ]
        tp = fp = fn = 0
        js = []
        for t in range(len(files) - 1):
            flow = cv2.resize(dis.calc(grey[t], grey[t + 1], None), (W, H), interpolation=cv2.INTER_AREA) / 2.0
            pred = inside(boundaries(flow, lam))
            ann = files[t].replace("JPEGImages", "Annotations").replace(".jpg", ".png")
            gt = cv2.resize(cv2.imread(ann, 0), (W, H), interpolation=cv2.INTER_NEAREST) > 128
            tp += int((pred & gt).sum())
            fp += int((pred & ~gt).sum())
            fn += int((~pred & gt).sum())
            js.append((pred & gt).sum() / max((pred | gt).sum(), 1))
        print(f"{s:15s} J {np.mean(js):.3f} P {tp / max(tp + fp, 1):.2f} R {tp / max(tp + fn, 1):.2f}")


if __name__ == "__main__":
    main()
