#!/usr/bin/env python3
"""Write a small optical-flow model in ONNX with the RAFT-style signature
romo's `OnnxFlow` reads: inputs `image1`, `image2` f32 [1, 3, H, W] (RGB,
dynamic H and W), output `flow` f32 [1, 2, H, W] (u, v in pixels, from
image1 to image2).

The network is classical, not learned: Lucas–Kanade (1981) on one scale,
two Gauss–Newton steps. Gray = channel mean, central-difference gradients
(Conv), brightness difference after warping image2 back by the current flow
(GridSample), structure tensor summed over a 9×9 window (Conv with a ones
kernel), 2×2 solve per pixel with a small Tikhonov term. It exists so the
ONNX flow path can be tested against a known answer without downloading
a RAFT checkpoint; any model with the same signature (RAFT, GMFlow exports)
is used the same way.

With `--bidirectional` the output is `flow` [1, 4, H, W]: the forward flow
then the backward one (image2 to image1, the same network with its inputs
swapped), the layout of `scripts/export_gmflow_onnx.py`'s GMFlow.

Usage: python3 scripts/make_lk_flow_onnx.py [--bidirectional] OUT.onnx
(needs `pip install onnx`)
"""
import sys

import numpy as np
import onnx
import onnx.compose
from onnx import TensorProto, helper, numpy_helper

WINDOW = 9
STEPS = 2
EPS = 1e-4


def main(out, bidirectional=False):
    nodes, inits = [], []

    def const(name, arr):
        inits.append(numpy_helper.from_array(np.asarray(arr, dtype=np.float32), name))
        return name

    def node(op, ins, out, **kw):
        nodes.append(helper.make_node(op, ins, [out], **kw))
        return out

    gray_w = const("gray_w", np.full((1, 3, 1, 1), 1.0 / 3.0))
    kx = const("kx", np.array([[[[-0.5, 0.0, 0.5]]]]))
    ky = const("ky", np.array([[[[-0.5], [0.0], [0.5]]]]))
    box = const("box", np.ones((1, 1, WINDOW, WINDOW)))
    eps = const("eps", np.array(EPS))
    two = const("two", np.array(2.0))
    one = const("one", np.array(1.0))
    p = WINDOW // 2

    g1 = node("Conv", ["image1", gray_w], "g1")
    g2 = node("Conv", ["image2", gray_w], "g2")
    ix = node("Conv", [g1, kx], "ix", pads=[0, 1, 0, 1])
    iy = node("Conv", [g1, ky], "iy", pads=[1, 0, 1, 0])

    def window(x, name):
        return node("Conv", [x, box], name, pads=[p, p, p, p])

    a = window(node("Mul", [ix, ix], "ixx"), "a")
    b = window(node("Mul", [ix, iy], "ixy"), "b")
    c = window(node("Mul", [iy, iy], "iyy"), "c")
    a = node("Add", [a, eps], "a_eps")
    c = node("Add", [c, eps], "c_eps")
    det = node("Sub", [node("Mul", [a, c], "ac"), node("Mul", [b, b], "bb")], "det")

    # Pixel grid in GridSample's normalised coordinates (align_corners=1):
    # x_n = 2 x / (W − 1) − 1, from the input's runtime shape.
    shape = node("Shape", ["image1"], "shape")
    hw = node("Slice", [shape, const_i("s2", [2], inits), const_i("s4", [4], inits)], "hw")
    hw_f = node("Cast", [hw], "hw_f", to=TensorProto.FLOAT)
    h_f = node("Gather", [hw_f, const_i("i0", 0, inits)], "h_f", axis=0)
    w_f = node("Gather", [hw_f, const_i("i1", 1, inits)], "w_f", axis=0)
    xs = node("Range", [const("zero", np.array(0.0)), w_f, one], "xs")
    ys = node("Range", ["zero", h_f, one], "ys")
    sx = node("Div", [two, node("Sub", [w_f, one], "w1")], "sx")
    sy = node("Div", [two, node("Sub", [h_f, one], "h1")], "sy")

    u = v = None
    for k in range(STEPS):
        if u is None:
            it = node("Sub", [g2, g1], f"it{k}")
        else:
            # grid[..., 0] = (x + u) · sx − 1, grid[..., 1] = (y + v) · sy − 1
            ux = node("Add", [node("Squeeze", [u, const_i(f"ax{k}", [0, 1], inits)], f"u2d{k}"),
                              xs], f"xu{k}")
            vy = node("Add", [node("Squeeze", [v, f"ax{k}"], f"v2d{k}"),
                              node("Unsqueeze", [ys, const_i(f"ay{k}", [1], inits)], f"ycol{k}")],
                      f"yv{k}")
            gx = node("Sub", [node("Mul", [ux, sx], f"gxs{k}"), one], f"gx{k}")
            gy = node("Sub", [node("Mul", [vy, sy], f"gys{k}"), one], f"gy{k}")
            grid = node("Unsqueeze", [node("Concat", [node("Unsqueeze", [gx, const_i(f"a2{k}", [2], inits)], f"gxu{k}"),
                                                      node("Unsqueeze", [gy, f"a2{k}"], f"gyu{k}")],
                                            f"grid3{k}", axis=2),
                                      const_i(f"a0{k}", [0], inits)], f"grid{k}")
            g2w = node("GridSample", [g2, grid], f"g2w{k}", align_corners=1, mode="bilinear",
                       padding_mode="border")
            # Linearised at the current flow: It = I2(x + d) − I1(x) − ∇I1 · d
            lin = node("Add", [node("Mul", [ix, u], f"ixu{k}"), node("Mul", [iy, v], f"iyv{k}")],
                       f"lin{k}")
            it = node("Sub", [node("Sub", [g2w, g1], f"dI{k}"), lin], f"it{k}")
        e = window(node("Mul", [ix, it], f"ixt{k}"), f"e{k}")
        f = window(node("Mul", [iy, it], f"iyt{k}"), f"f{k}")
        # [a b; b c] [u v]ᵀ = −[e f]ᵀ
        un = node("Div", [node("Sub", [node("Mul", [b, f], f"bf{k}"), node("Mul", [c, e], f"ce{k}")],
                               f"unum{k}"), det], f"u{k}")
        vn = node("Div", [node("Sub", [node("Mul", [b, e], f"be{k}"), node("Mul", [a, f], f"af{k}")],
                               f"vnum{k}"), det], f"v{k}")
        u, v = un, vn
    nodes.append(helper.make_node("Concat", [u, v], ["flow"], axis=1))

    dims = ["batch", 3, "height", "width"]
    graph = helper.make_graph(
        nodes,
        "lucas_kanade_flow",
        [helper.make_tensor_value_info("image1", TensorProto.FLOAT, dims),
         helper.make_tensor_value_info("image2", TensorProto.FLOAT, dims)],
        [helper.make_tensor_value_info("flow", TensorProto.FLOAT, ["batch", 2, "height", "width"])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)],
                              producer_name="romosplat scripts/make_lk_flow_onnx.py")
    model.ir_version = 8
    if bidirectional:
        model = both_ways(model)
    onnx.checker.check_model(model)
    onnx.save(model, out)


def both_ways(fwd):
    """One model running `fwd` on (image1, image2) and on (image2, image1),
    its outputs concatenated to [1, 4, H, W]."""
    bwd = onnx.compose.add_prefix(fwd, "bwd_")
    g = fwd.graph
    nodes = list(g.node) + [
        helper.make_node("Identity", ["image2"], ["bwd_image1"]),
        helper.make_node("Identity", ["image1"], ["bwd_image2"]),
    ] + list(bwd.graph.node)
    for n in nodes:
        n.output[:] = ["fwd_flow" if o == "flow" else o for o in n.output]
    nodes.append(helper.make_node("Concat", ["fwd_flow", "bwd_flow"], ["flow"], axis=1))
    out = helper.make_tensor_value_info("flow", TensorProto.FLOAT, ["batch", 4, "height", "width"])
    graph = helper.make_graph(nodes, "lucas_kanade_flow_both_ways", list(g.input), [out],
                              list(g.initializer) + list(bwd.graph.initializer))
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)],
                              producer_name=fwd.producer_name)
    model.ir_version = 8
    return model


def const_i(name, v, inits):
    inits.append(numpy_helper.from_array(np.asarray(v, dtype=np.int64), name))
    return name


if __name__ == "__main__":
    args = sys.argv[1:]
    bidir = "--bidirectional" in args
    args = [a for a in args if a != "--bidirectional"]
    if len(args) != 1:
        sys.exit("usage: make_lk_flow_onnx.py [--bidirectional] OUT.onnx")
    main(args[0], bidir)
