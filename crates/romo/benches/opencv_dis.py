#!/usr/bin/env python3
"""OpenCV DIS MEDIUM on the Sintel pairs, for comparison with
`cargo bench -p romo --bench flow_sintel`. Prints JSON like the Rust bench.
Usage: python3 crates/romo/benches/opencv_dis.py [SINTEL_DIR]"""
import json, os, sys, time
import cv2, numpy as np

d = sys.argv[1] if len(sys.argv) > 1 else "/work/shared/data/sintel-flow"
cv2.setNumThreads(2)
reps = int(os.environ.get("REPS", "3"))

def read_flo(p):
    with open(p, "rb") as f:
        assert f.read(4) == b"PIEH"
        w, h = np.frombuffer(f.read(8), np.int32)
        return np.frombuffer(f.read(), np.float32).reshape(h, w, 2)

rows = []
for n in sorted(os.listdir(d)):
    a = cv2.imread(f"{d}/{n}/frame1.png", cv2.IMREAD_GRAYSCALE)
    b = cv2.imread(f"{d}/{n}/frame2.png", cv2.IMREAD_GRAYSCALE)
    gt = read_flo(f"{d}/{n}/flow.flo")
    noc = cv2.imread(f"{d}/{n}/occlusions.png", cv2.IMREAD_GRAYSCALE) < 128
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    ts = []
    for _ in range(reps):
        t = time.perf_counter(); fl = dis.calc(a, b, None); ts.append((time.perf_counter() - t) * 1e3)
    e = np.linalg.norm(fl - gt, axis=2)
    rows.append(dict(pair=n, small_motion=n.startswith(("alley", "cave")), epe_all=float(e.mean()),
                     epe_noc=float(e[noc].mean()), ms_median=float(np.median(ts))))
def mean(s, k):
    v = [r[k] for r in rows if r["small_motion"] == s]; return sum(v) / len(v)
print(json.dumps(dict(method="OpenCV DIS MEDIUM", threads=2,
    small=dict(epe_all=mean(True, "epe_all"), epe_noc=mean(True, "epe_noc"), ms=mean(True, "ms_median")),
    large=dict(epe_all=mean(False, "epe_all"), epe_noc=mean(False, "epe_noc"), ms=mean(False, "ms_median")),
    pairs=rows), indent=1))
