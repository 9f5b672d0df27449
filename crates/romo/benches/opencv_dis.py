#!/usr/bin/env python3
"""OpenCV DIS MEDIUM on the Sintel pairs, for comparison with
`cargo bench -p romo --bench flow_sintel` (which starts this script with
`--serve` and interleaves its runs with ours, so both see the same load).

Standalone: python3 crates/romo/benches/opencv_dis.py [SINTEL_DIR]
    prints JSON like the Rust bench (REPS runs per pair, median time).
Server:     python3 crates/romo/benches/opencv_dis.py --serve SINTEL_DIR
    prints "ready <cv2 version>", then answers one JSON line per request
    line "run <pair>" (one timed calc: {"ms", "epe_all", "epe_noc"}).
Both use 2 threads (cv2.setNumThreads(2))."""
import json, os, sys, time

try:
    import cv2, numpy as np
except Exception as e:  # reported by the Rust bench
    print(f"unavailable {type(e).__name__}: {e}".replace("\n", " "), flush=True)
    sys.exit(0)

cv2.setNumThreads(2)


def read_flo(p):
    with open(p, "rb") as f:
        assert f.read(4) == b"PIEH"
        w, h = np.frombuffer(f.read(8), np.int32)
        return np.frombuffer(f.read(), np.float32).reshape(h, w, 2)


class Pair:
    def __init__(self, d, n):
        self.a = cv2.imread(f"{d}/{n}/frame1.png", cv2.IMREAD_GRAYSCALE)
        self.b = cv2.imread(f"{d}/{n}/frame2.png", cv2.IMREAD_GRAYSCALE)
        self.gt = read_flo(f"{d}/{n}/flow.flo")
        self.noc = cv2.imread(f"{d}/{n}/occlusions.png", cv2.IMREAD_GRAYSCALE) < 128
        self.dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)

    def run(self):
        t = time.perf_counter()
        fl = self.dis.calc(self.a, self.b, None)
        ms = (time.perf_counter() - t) * 1e3
        e = np.linalg.norm(fl - self.gt, axis=2)
        return dict(ms=ms, epe_all=float(e.mean()), epe_noc=float(e[self.noc].mean()))


def serve(d):
    print(f"ready {cv2.__version__}", flush=True)
    pairs = {}
    for line in sys.stdin:
        cmd, _, n = line.strip().partition(" ")
        if cmd != "run":
            break
        if n not in pairs:
            pairs[n] = Pair(d, n)
        print(json.dumps(pairs[n].run()), flush=True)


def standalone(d):
    reps = int(os.environ.get("REPS", "5"))
    rows = []
    for n in sorted(os.listdir(d)):
        p = Pair(d, n)
        rs = [p.run() for _ in range(reps)]
        rows.append(dict(pair=n, small_motion=n.startswith(("alley", "cave")), epe_all=rs[-1]["epe_all"],
                         epe_noc=rs[-1]["epe_noc"], ms_median=float(np.median([r["ms"] for r in rs]))))

    def mean(s, k):
        v = [r[k] for r in rows if r["small_motion"] == s]
        return sum(v) / len(v)

    print(json.dumps(dict(method="OpenCV DIS MEDIUM", version=cv2.__version__, threads=2,
                          small=dict(epe_all=mean(True, "epe_all"), epe_noc=mean(True, "epe_noc"), ms=mean(True, "ms_median")),
                          large=dict(epe_all=mean(False, "epe_all"), epe_noc=mean(False, "epe_noc"), ms=mean(False, "ms_median")),
                          pairs=rows), indent=1))


if __name__ == "__main__":
    args = sys.argv[1:]
    if args and args[0] == "--serve":
        serve(args[1] if len(args) > 1 else "/work/shared/data/sintel-flow")
    else:
        standalone(args[0] if args else "/work/shared/data/sintel-flow")
