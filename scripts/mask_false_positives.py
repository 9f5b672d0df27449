#!/usr/bin/env python3
"""Where a mask's false positives lie: how far each wrongly-moving pixel is
from the annotated object. Tells boundary error (false positives hugging the
object) from other moving things the annotation leaves out (far ones).

Usage: mask_false_positives.py PRED_ROOT GT_ROOT [SEQ ...]
PRED_ROOT/<seq>/masks/<frame>.jpg.png are keep-masks (255 keep, 0 moving),
as the `davis` example writes them (/tmp/romo_davis); GT_ROOT/<seq>/<frame>.png
are DAVIS annotations (255 object). Prints one JSON line per sequence: pooled
J, false positives as a fraction of the object's area, and the fractions of
the false positives within 3, 8 and 20 px of the object (Euclidean distance
transform), and the mean per-frame J with each mask dilated (negative) or
eroded (positive) by 1–3 px: where J peaks at 0 the boundaries sit where
they should. Needs numpy, scipy and pillow.
"""
import json
import os
import sys

import numpy as np
from PIL import Image
from scipy import ndimage

RADII = (3, 8, 20)
SHIFTS = (-2, -1, 0, 1, 2, 3)


def shifted(mask, k):
    if k > 0:
        return ndimage.binary_erosion(mask, iterations=k)
    if k < 0:
        return ndimage.binary_dilation(mask, iterations=-k)
    return mask


def jaccard(pred, gt):
    union = int((pred | gt).sum())
    return int((pred & gt).sum()) / union if union else 1.0


def sequence(pred_dir, gt_dir):
    tp = fp = fn = 0
    near = [0] * len(RADII)
    frame_j = {k: [] for k in SHIFTS}
    for name in sorted(os.listdir(pred_dir)):
        stem = name.split(".")[0]
        gt_path = os.path.join(gt_dir, stem + ".png")
        if not os.path.exists(gt_path):
            sys.exit(f"{gt_path}: no annotation for {os.path.join(pred_dir, name)}")
        pred = np.array(Image.open(os.path.join(pred_dir, name)).convert("L")) < 128
        gt = np.array(Image.open(gt_path).convert("L")) > 128
        if pred.shape != gt.shape:
            sys.exit(f"{os.path.join(pred_dir, name)}: size {pred.shape} but {gt_path} is {gt.shape}")
        wrong = pred & ~gt
        dist = ndimage.distance_transform_edt(~gt)
        tp += int((pred & gt).sum())
        fp += int(wrong.sum())
        fn += int((~pred & gt).sum())
        for i, r in enumerate(RADII):
            near[i] += int((wrong & (dist <= r)).sum())
        for k in SHIFTS:
            frame_j[k].append(jaccard(shifted(pred, k), gt))
    union = tp + fp + fn
    return {
        "j_pooled": tp / union if union else 1.0,
        "fp_over_object": fp / max(tp + fn, 1),
        **{f"fp_within_{r}px": n / max(fp, 1) for r, n in zip(RADII, near)},
        **{f"j_shift_{k}px": float(np.mean(v)) for k, v in frame_j.items()},
    }


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    pred_root, gt_root = sys.argv[1], sys.argv[2]
    seqs = sys.argv[3:] or sorted(os.listdir(pred_root))
    for seq in seqs:
        res = sequence(os.path.join(pred_root, seq, "masks"), os.path.join(gt_root, seq))
        print(json.dumps({"sequence": seq, **{k: round(v, 3) for k, v in res.items()}}))


if __name__ == "__main__":
    main()
