#!/usr/bin/python3
"""YOLOv7-tiny as an ONNX graph with random weights, in the official export layout.

The paper's detector is YOLOv7-tiny; no trained weights exist here, so this builds its architecture
(yolov7-tiny.yaml of the official repository, WongKinYiu/yolov7) with random weights from a fixed seed,
as `export.py --grid` exports it after fusing BatchNorm and the implicit layers into the convolutions:

  input  "images" 1x3x640x640 (RGB, scaled 1/255)
  output "output" 1x25200x85: per row cx, cy, w, h in input pixels, objectness, 80 class scores
         (rows: stride 8 then 16 then 32; inside a stride anchor-major, then grid row, then column).

Architecture (every Conv is conv + bias + LeakyReLU(0.1), BN fused):
  backbone: Conv 32 3x3/2, Conv 64 3x3/2, ELAN-tiny(32 -> 64); MP, ELAN-tiny(64 -> 128);
            MP, ELAN-tiny(128 -> 256); MP, ELAN-tiny(256 -> 512)
            ELAN-tiny(c -> o): a = Conv c 1x1, b = Conv c 1x1, c1 = Conv c 3x3 (b), c2 = Conv c 3x3 (c1),
            Conv o 1x1 (concat[c2, c1, b, a])
  neck:     SPPCSPC-tiny: a = Conv 256 1x1, b = Conv 256 1x1 (from the same input), max-pools 5/9/13 of b,
            Conv 256 1x1 (concat[pool13, pool9, pool5, b]), concat with a, Conv 256 1x1   (layer 37)
            top-down PAN: Conv 128, upsample x2, concat Conv 128 (P4 = layer 21), ELAN-tiny(64 -> 128),
            Conv 64, upsample x2, concat Conv 64 (P3 = layer 14), ELAN-tiny(32 -> 64)           (layer 57)
            bottom-up: Conv 128 3x3/2, concat 47, ELAN-tiny(64 -> 128) (65); Conv 256 3x3/2,
            concat 37, ELAN-tiny(128 -> 256) (73)
  heads:    Conv 128 3x3 (57), Conv 256 3x3 (65), Conv 512 3x3 (73); IDetect: 1x1 conv to 3 x 85 per
            level, anchors P3 (10,13 16,30 33,23), P4 (30,61 62,45 59,119), P5 (116,90 156,198 373,326)
            decoding in the graph as IDetect exports it: y = sigmoid(x), split (2, 2, 81) on the last
            axis; xy = y_xy * 2 stride + stride (grid - 0.5); wh = y_wh^2 * 4 anchor; concat.

Needs Debian's python3-onnx (and python3-numpy). Usage:
  scripts/make_yolov7_tiny_onnx.py --out yolov7_tiny_random.onnx [--seed 7] [--size 640]
"""
import argparse
import sys

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

NUM_CLASSES = 80
NO = NUM_CLASSES + 5
ANCHORS = [[10, 13, 16, 30, 33, 23], [30, 61, 62, 45, 59, 119], [116, 90, 156, 198, 373, 326]]
STRIDES = [8, 16, 32]
OPSET = 12  # the official export's default


class Graph:
    def __init__(self, seed):
        self.rng = np.random.default_rng(seed)
        self.nodes = []
        self.inits = []
        self.count = 0

    def name(self, prefix):
        self.count += 1
        return f"{prefix}_{self.count}"

    def const(self, array, prefix="const"):
        n = self.name(prefix)
        self.inits.append(numpy_helper.from_array(np.asarray(array), n))
        return n

    def node(self, op, inputs, prefix=None, **attrs):
        out = self.name(prefix or op.lower())
        self.nodes.append(helper.make_node(op, inputs, [out], name=out, **attrs))
        return out

    def conv(self, x, c_in, c_out, k=1, s=1, act=True, bias=None):
        # He-style scale for LeakyReLU keeps activations of the random network in a sane range.
        w = self.rng.normal(0.0, np.sqrt(2.0 / (c_in * k * k)), (c_out, c_in, k, k)).astype(np.float32)
        b = np.zeros(c_out, np.float32) if bias is None else bias.astype(np.float32)
        y = self.node("Conv", [x, self.const(w, "w"), self.const(b, "b")], "conv", kernel_shape=[k, k],
                      strides=[s, s], pads=[k // 2] * 4)
        return self.node("LeakyRelu", [y], alpha=0.1) if act else y

    def concat(self, xs, axis=1):
        return self.node("Concat", xs, axis=axis)

    def maxpool(self, x, k, s):
        pad = (k - s) // 2 if s == 1 else 0
        return self.node("MaxPool", [x], kernel_shape=[k, k], strides=[s, s], pads=[pad] * 4)

    def upsample(self, x):
        roi = self.const(np.zeros(0, np.float32), "roi")
        scales = self.const(np.array([1, 1, 2, 2], np.float32), "scales")
        return self.node("Resize", [x, roi, scales], mode="nearest", coordinate_transformation_mode="asymmetric",
                         nearest_mode="floor")

    def elan_tiny(self, x, c_in, c, c_out):
        a = self.conv(x, c_in, c, 1)
        b = self.conv(x, c_in, c, 1)
        c1 = self.conv(b, c, c, 3)
        c2 = self.conv(c1, c, c, 3)
        return self.conv(self.concat([c2, c1, b, a]), 4 * c, c_out, 1)


def detect_level(g, x, c_in, level, size, full_constants):
    """IDetect for one level, exported with --grid: 1x(3*ny*nx)x85 rows in input pixels."""
    stride = STRIDES[level]
    ny = nx = size // stride
    # YOLO's prior init of the head biases: objectness ~ 8 objects per 640 image, class ~ 1/80.
    bias = np.zeros((3, NO), np.float32)
    bias[:, 4] = np.log(8.0 / (640.0 / stride) ** 2)
    bias[:, 5:] = np.log(0.6 / (NUM_CLASSES - 0.99))
    y = g.conv(x, c_in, 3 * NO, 1, act=False, bias=bias.reshape(-1))
    y = g.node("Reshape", [y, g.const(np.array([1, 3, NO, ny, nx], np.int64), "shape")])
    y = g.node("Transpose", [y], perm=[0, 1, 3, 4, 2])  # 1 x 3 x ny x nx x 85
    y = g.node("Sigmoid", [y])
    # As IDetect exports it (yolov7 models/yolo.py, ONNX branch): xy, wh, conf = y.split((2, 2, nc + 1), 4);
    # xy = xy * (2 * stride) + stride * (grid - 0.5); wh = wh ** 2 * (4 * anchor_grid); cat on axis 4.
    xy, wh, conf = (g.name("split") for _ in range(3))
    g.nodes.append(helper.make_node("Split", [y], [xy, wh, conf], name=xy, axis=4, split=[2, 2, NO - 4]))
    xv, yv = np.meshgrid(np.arange(nx, dtype=np.float32), np.arange(ny, dtype=np.float32))
    grid = np.stack((xv, yv), 2).reshape(1, 1, ny, nx, 2).astype(np.float32)
    anchor_grid = np.array(ANCHORS[level], np.float32).reshape(1, 3, 1, 1, 2)
    if full_constants:
        # OpenCV 4.6's ONNX importer fails on the broadcast Add of the (1, 1, ny, nx, 2) grid
        # (shape_utils.hpp total(): assertion), so by default both constants are stored at full shape:
        # the same values and the same output, without broadcasting.
        grid = np.broadcast_to(grid, (1, 3, ny, nx, 2)).copy()
        anchor_grid = np.broadcast_to(anchor_grid, (1, 3, ny, nx, 2)).copy()
    xy = g.node("Mul", [xy, g.const(np.array(2.0 * stride, np.float32))])
    xy = g.node("Add", [xy, g.const(stride * (grid - 0.5), "grid")])
    wh = g.node("Pow", [wh, g.const(np.array(2.0, np.float32))])
    wh = g.node("Mul", [wh, g.const(4.0 * anchor_grid, "anchor_grid")])
    y = g.node("Concat", [xy, wh, conf], axis=4)
    return g.node("Reshape", [y, g.const(np.array([1, -1, NO], np.int64), "shape")])


def build(seed, size, full_constants=True):
    g = Graph(seed)
    x = "images"
    # Backbone.
    x = g.conv(x, 3, 32, 3, 2)                   # 0  P1/2
    x = g.conv(x, 32, 64, 3, 2)                  # 1  P2/4
    x = g.elan_tiny(x, 64, 32, 64)               # 7
    x = g.maxpool(x, 2, 2)                       # 8  P3/8
    p3 = g.elan_tiny(x, 64, 64, 128)             # 14
    x = g.maxpool(p3, 2, 2)                      # 15 P4/16
    p4 = g.elan_tiny(x, 128, 128, 256)           # 21
    x = g.maxpool(p4, 2, 2)                      # 22 P5/32
    p5 = g.elan_tiny(x, 256, 256, 512)           # 28
    # SPPCSPC-tiny.
    a = g.conv(p5, 512, 256, 1)
    b = g.conv(p5, 512, 256, 1)
    pools = [g.maxpool(b, k, 1) for k in (5, 9, 13)]
    s = g.conv(g.concat([pools[2], pools[1], pools[0], b]), 1024, 256, 1)
    n37 = g.conv(g.concat([s, a]), 512, 256, 1)  # 37
    # Top-down.
    x = g.upsample(g.conv(n37, 256, 128, 1))
    x = g.concat([g.conv(p4, 256, 128, 1), x])
    n47 = g.elan_tiny(x, 256, 64, 128)           # 47
    x = g.upsample(g.conv(n47, 128, 64, 1))
    x = g.concat([g.conv(p3, 128, 64, 1), x])
    n57 = g.elan_tiny(x, 128, 32, 64)            # 57
    # Bottom-up.
    x = g.concat([g.conv(n57, 64, 128, 3, 2), n47])
    n65 = g.elan_tiny(x, 256, 64, 128)           # 65
    x = g.concat([g.conv(n65, 128, 256, 3, 2), n37])
    n73 = g.elan_tiny(x, 512, 128, 256)          # 73
    # Heads.
    outs = [detect_level(g, g.conv(n57, 64, 128, 3), 128, 0, size, full_constants),
            detect_level(g, g.conv(n65, 128, 256, 3), 256, 1, size, full_constants),
            detect_level(g, g.conv(n73, 256, 512, 3), 512, 2, size, full_constants)]
    g.nodes.append(helper.make_node("Concat", outs, ["output"], name="output", axis=1))
    rows = 3 * sum((size // s) ** 2 for s in STRIDES)
    graph = helper.make_graph(
        g.nodes, "yolov7_tiny_random",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, size, size])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, [1, rows, NO])], g.inits)
    model = helper.make_model(graph, producer_name="stillpoint make_yolov7_tiny_onnx.py",
                              opset_imports=[helper.make_opsetid("", OPSET)])
    model.doc_string = f"YOLOv7-tiny architecture, RANDOM weights (seed {seed}); not a trained detector"
    onnx.checker.check_model(model)
    return model


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="output .onnx file")
    ap.add_argument("--seed", type=int, default=7, help="random seed of the weights")
    ap.add_argument("--size", type=int, default=640, help="input size (multiple of 32)")
    ap.add_argument("--broadcast-constants", action="store_true",
                    help="grid (1,1,ny,nx,2) and anchors (1,3,1,1,2) broadcast as torch exports them "
                         "(OpenCV 4.6 cannot load that graph)")
    args = ap.parse_args()
    if args.size % 32 != 0:
        sys.exit("--size must be a multiple of 32")
    model = build(args.seed, args.size, full_constants=not args.broadcast_constants)
    params = sum(int(np.prod(t.dims)) for t in model.graph.initializer if t.name.startswith(("w_", "b_")))
    onnx.save(model, args.out)
    print(f"{args.out}: YOLOv7-tiny, random weights (seed {args.seed}), {params} parameters, "
          f"input 1x3x{args.size}x{args.size}, output 1x{3 * sum((args.size // s) ** 2 for s in STRIDES)}x{NO}")


if __name__ == "__main__":
    main()
