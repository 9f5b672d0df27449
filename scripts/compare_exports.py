#!/usr/bin/env python3
"""Compare what PlayCanvas splat-transform decoded from our exports with the
exact parameters (sample_truth.csv, INRIA PLY column layout, written by the
`export::tests::write_samples_*` test).

Usage: compare_exports.py TRUTH.csv FORMAT=DECODED.csv [...]
FORMAT is ply, spz or splat. Each comparison uses that format's quantisation
bound (see crates/splat/src/export/{spz,web_splat}.rs). Prints one JSON line
per file with the largest error per attribute; exits 1 on any violation.
"""
import json
import sys

import numpy as np

SH_C0 = 0.28209479177387814


def load(path):
    with open(path) as f:
        header = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, i] for i, name in enumerate(header)}


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def quats(t):
    q = np.stack([t["rot_0"], t["rot_1"], t["rot_2"], t["rot_3"]], axis=1)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def quat_err(a, b):
    """Largest component error up to the sign ambiguity q ~ -q."""
    s = np.sign(np.sum(a * b, axis=1, keepdims=True))
    s[s == 0] = 1
    return np.abs(a - s * b).max()


def rest_cols(t):
    return sorted((c for c in t if c.startswith("f_rest_")), key=lambda c: int(c[7:]))


def compare(fmt, truth, dec):
    n = len(truth["x"])
    errs = {"rows": (len(dec["x"]), n)}
    bounds = {}
    if len(dec["x"]) != n:
        return errs, {"rows": "count mismatch"}
    xyz = lambda t: np.stack([t["x"], t["y"], t["z"]], axis=1)
    ls = lambda t: np.stack([t["scale_0"], t["scale_1"], t["scale_2"]], axis=1)
    dc = lambda t: np.stack([t["f_dc_0"], t["f_dc_1"], t["f_dc_2"]], axis=1)
    if fmt == "splat":
        # .splat is importance-sorted: match rows on exact positions.
        key = {tuple(np.round(p, 5)): i for i, p in enumerate(xyz(truth))}
        order = np.array([key[tuple(np.round(p, 5))] for p in xyz(dec)])
        truth = {k: v[order] for k, v in truth.items()}
    e = {
        "position": np.abs(xyz(dec) - xyz(truth)).max(),
        "log_scale": np.abs(ls(dec) - ls(truth)).max(),
        "opacity": np.abs(sigmoid(dec["opacity"]) - sigmoid(truth["opacity"])).max(),
        "rotation": quat_err(quats(dec), quats(truth)),
    }
    if fmt == "ply":
        e["dc"] = np.abs(dc(dec) - dc(truth)).max()
        rt, rd = rest_cols(truth), rest_cols(dec)
        e["sh_rest"] = max(np.abs(dec[a] - truth[b]).max() for a, b in zip(rd, rt)) if rt else 0.0
        b = {"position": 1e-6, "log_scale": 1e-6, "opacity": 1e-6, "rotation": 1e-6, "dc": 1e-6, "sh_rest": 1e-6}
        if rd != rt:
            e["sh_rest"] = float("inf")
    elif fmt == "spz":
        e["dc"] = np.abs(dc(dec) - dc(truth)).max()
        rt, rd = rest_cols(truth), rest_cols(dec)
        k1 = len(rt) // 3  # higher-order coefficients per channel
        worst = 0.0
        for c in range(3):
            for j in range(k1):
                col = c * k1 + j
                bucket = 8 if j < 3 else 16
                err = np.abs(dec[rd[col]] - truth[rt[col]]).max()
                worst = max(worst, err / ((0.5 + bucket / 2) / 128))
        e["sh_rest_rel"] = worst  # ≤ 1 means within the bucket bound
        b = {
            "position": 0.5 / 4096 + 1e-6,
            "log_scale": 1 / 32 + 1e-5,
            "opacity": 0.5 / 255 + 1e-5,
            "rotation": 2.2e-3,
            "dc": 0.5 / (0.15 * 255) + 1e-5,
            "sh_rest_rel": 1.0 + 1e-4,
        }
    elif fmt == "splat":
        # Colour in [0, 1] after truncation to u8; compare in colour space.
        col_t = np.clip(0.5 + SH_C0 * dc(truth), 0, 1)
        col_d = 0.5 + SH_C0 * dc(dec)
        e["colour"] = np.abs(col_d - col_t).max()
        b = {
            "position": 1e-6,
            "log_scale": 1e-5,
            "opacity": 1 / 255 + 1e-5,
            # truncation of q·128 + 128: ≤ 1/128 per component before renormalising
            "rotation": 2.5 / 128,
            "colour": 1 / 255 + 1e-5,
        }
    else:
        raise SystemExit(f"unknown format {fmt}")
    bad = {k: (float(e[k]), b[k]) for k in e if not e[k] <= b[k]}
    return {k: float(v) for k, v in e.items()}, bad


def main():
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    truth = load(sys.argv[1])
    failed = False
    for arg in sys.argv[2:]:
        fmt, path = arg.split("=", 1)
        errs, bad = compare(fmt, truth, load(path))
        print(json.dumps({"format": fmt, "file": path, "rows": len(truth["x"]), "max_error": errs, "violations": bad}))
        failed |= bool(bad)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
