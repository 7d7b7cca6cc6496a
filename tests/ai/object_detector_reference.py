"""Independent PyTorch run of the NanoDet TensorFlow.js graph model, the reference of
tests/ai/object_detector_test.cpp.

The graph (model.json's GraphDef nodes and the weights manifest) is interpreted node by node with
torch.nn.functional in NCHW (TensorFlow's NHWC operands permuted at each convolution, pooling
and resize), the weights read with numpy. For one 416 x 416 image (no resize, no tiles): the
class scores and box-side distributions decoded as the GFL head does (sigmoid scores, the
softmax expectation of each side's 11 bins times the stride from the cell centre), class-wise
non-maximum suppression at IoU 0.6. Prints one JSON list of [class index, score, x0, y0, x1, y1].

Usage: object_detector_reference.py MODEL.json IMAGE.png [--threshold T]
"""
import argparse
import base64
import json
import os

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

MEAN_BGR = np.array([103.53, 116.28, 123.675], dtype=np.float32)
STD_BGR = np.array([57.375, 57.12, 58.395], dtype=np.float32)


def read_weights(model, folder):
    weights = {}
    for group in model["weightsManifest"]:
        data = b"".join(open(os.path.join(folder, path), "rb").read() for path in group["paths"])
        offset = 0
        for entry in group["weights"]:
            count = int(np.prod(entry["shape"])) if entry["shape"] else 1
            stored = entry.get("quantization", {}).get("dtype", entry["dtype"])
            dtype = {"float32": np.float32, "int32": np.int32, "float16": np.float16}[stored]
            values = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            offset += values.nbytes
            array = values.astype(np.int64 if entry["dtype"] == "int32" else np.float32).reshape(entry["shape"])
            weights[entry["name"]] = torch.from_numpy(array.copy())
    return weights


def ints(attribute):
    return [int(v) for v in attribute["list"]["i"]]


def run_graph(nodes, weights, image):
    values = dict(weights)
    values["input_1"] = image

    def operand(name):
        base, _, index = name.partition(":")
        value = values[base]
        return value[int(index or 0)] if isinstance(value, list) else value

    pending = [n for n in nodes if n["op"] not in ("Const", "Placeholder")]
    while pending:  # nodes in any order: run each once its inputs are there
        waiting = []
        for node in pending:
            inputs = [i for i in node.get("input", []) if not i.startswith("^")]
            if any(i.partition(":")[0] not in values for i in inputs):
                waiting.append(node)
                continue
            x = [operand(i) for i in inputs]
            op, attr = node["op"], node.get("attr", {})
            if op == "Identity":
                out = x[0]
            elif op in ("Pad", "PadV2"):
                pads = [v for pair in reversed(x[1].tolist()) for v in pair]
                out = F.pad(x[0], pads, value=float(x[2]) if op == "PadV2" else 0.0)
            elif op == "Transpose":
                out = x[0].permute(*x[1].tolist())
            elif op == "Conv2D":
                assert base64.b64decode(attr["padding"]["s"]) == b"VALID"
                stride, dilation = ints(attr["strides"])[1:3], ints(attr["dilations"])[1:3]
                nchw, kernel = x[0].permute(0, 3, 1, 2), x[1].permute(3, 2, 0, 1)
                out = F.conv2d(nchw, kernel, stride=stride, dilation=dilation, groups=nchw.shape[1] // kernel.shape[1]).permute(0, 2, 3, 1)
            elif op in ("Add", "AddV2"):
                out = x[0] + x[1]
            elif op == "LeakyRelu":
                out = F.leaky_relu(x[0], attr["alpha"]["f"])
            elif op == "MaxPool":
                out = F.max_pool2d(x[0].permute(0, 3, 1, 2), ints(attr["ksize"])[1:3], ints(attr["strides"])[1:3]).permute(0, 2, 3, 1)
            elif op == "ConcatV2":
                out = torch.cat(x[:-1], int(x[-1]))
            elif op == "ResizeBilinear":
                out = F.interpolate(x[0].permute(0, 3, 1, 2), size=tuple(x[1].tolist()), mode="bilinear", align_corners=False).permute(0, 2, 3, 1)
            elif op == "SplitV":
                out = list(torch.split(x[0], x[1].tolist(), int(x[2])))
            elif op == "Sigmoid":
                out = torch.sigmoid(x[0])
            elif op == "Reshape":
                out = x[0].reshape(x[1].tolist())
            elif op == "SparseToDense":
                out = torch.full(x[1].tolist(), int(x[3]), dtype=torch.int64)
                for k in range(x[0].shape[0]):
                    out[tuple(x[0][k].tolist())] = x[2] if x[2].dim() == 0 else x[2][k]
            else:
                raise SystemExit(f"operation {op} not in the reference")
            values[node["name"]] = out
        if len(waiting) == len(pending):
            raise SystemExit("the graph has inputs no node defines")
        pending = waiting
    return {name: operand(name)[0] for name in ("Identity", "Identity_1", "Identity_2", "Identity_3", "Identity_4", "Identity_5")}


def iou(a, b):
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    if w <= 0 or h <= 0:
        return 0.0
    inter = w * h
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("model")
    parser.add_argument("image")
    parser.add_argument("--threshold", type=float, default=0.35)
    args = parser.parse_args()
    model = json.load(open(args.model))
    weights = read_weights(model, os.path.dirname(os.path.abspath(args.model)))
    rgb = np.asarray(Image.open(args.image).convert("RGB"), dtype=np.float32)
    assert rgb.shape[:2] == (416, 416), "the reference takes a 416 x 416 image"
    bgr = (rgb[:, :, ::-1] - MEAN_BGR) / STD_BGR
    image = torch.from_numpy(np.ascontiguousarray(bgr.transpose(2, 0, 1)))[None]
    with torch.no_grad():
        outputs = run_graph(model["modelTopology"]["node"], weights, image)
    levels = {}
    for tensor in outputs.values():
        side = int(round(tensor.shape[0] ** 0.5))
        levels.setdefault(416 // side, {})["scores" if tensor.shape[1] == 80 else "sides"] = tensor
    candidates = []
    for stride, level in sorted(levels.items()):
        best, classes = level["scores"].max(1)
        sides = (torch.softmax(level["sides"].reshape(-1, 4, 11), 2) * torch.arange(11.0)).sum(2) * stride
        cells = 416 // stride
        for cell in torch.nonzero(best > args.threshold).flatten().tolist():
            cx, cy = (cell % cells + 0.5) * stride, (cell // cells + 0.5) * stride
            l, t, r, b = sides[cell].tolist()
            box = [min(max(v, 0.0), 415.0) for v in (cx - l, cy - t, cx + r, cy + b)]
            candidates.append([int(classes[cell]), float(best[cell])] + box)
    candidates.sort(key=lambda c: -c[1])
    kept = []
    for c in candidates:
        if not any(k[0] == c[0] and iou(k[2:], c[2:]) > 0.6 for k in kept):
            kept.append(c)
    print(json.dumps(kept[:100]))


if __name__ == "__main__":
    main()
