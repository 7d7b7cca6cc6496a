"""Trains the correspondence filter (include/hanzo/fusion/vision/correspondence_filter.hpp) on the
project's own data and writes models/trained/correspondence_filter.json.

Data: camera images of simulated scenarios (`hanzo-fusion sim`, images written by `export
dataset`), each warped by random homographies (the four corners moved by up to a fifth of the
image, as SuperPoint's homographic adaptation); `hanzo-fusion features match --putative-out` gives
every pair's mutual nearest neighbours as the filter's inputs, labelled correct within 3 px of the
true homography. Training scenarios: drone, ar_handheld; held back for the evaluation printed at
the end: warehouse_robot (another place, another camera).

Network: Yi et al., CVPR 2018, with context normalization; loss: the mean binary cross-entropy of
inliers plus that of outliers (classes balanced per pair). On the 2-core CPU: minutes.

Usage: train_correspondence_filter.py --cli build/apps/hanzo-fusion --work build/train-correspondence-filter
       [--out models/trained/correspondence_filter.json] [--pairs-per-image 4] [--epochs 30] [--seed 7]
"""
import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image
from torch import nn

TRAIN_SCENARIOS = ["drone", "ar_handheld"]
HELD_BACK_SCENARIOS = ["warehouse_robot"]
WIDTH, BLOCKS = 64, 4


def run(command):
    completed = subprocess.run(command, capture_output=True, text=True)
    if completed.returncode != 0:
        sys.exit(f"failed: {' '.join(command)}\n{completed.stderr}")
    return completed.stdout


def camera_images(cli, scenario, work, every):
    """PNG camera images of a simulated scenario (the first camera's folder of the exported dataset)."""
    sim = work / f"sim_{scenario}"
    dataset = work / f"images_{scenario}"
    if not dataset.exists():
        run([cli, "sim", f"examples/scenarios/{scenario}.yaml", "--out", str(sim), "--duration", "30", "--no-foxglove",
             "--image-compression", "png"])
        run([cli, "export", "dataset", str(sim / "sensors.mcap"), "--trajectory", str(sim / "ground_truth.tum"), "--calib",
             str(sim / "calibration.yaml"), "--out", str(dataset), "--every", str(every)])
    images = sorted(p for p in dataset.rglob("*.png") if "image" in p.parent.name or "cam" in p.parent.name)
    if not images:
        sys.exit(f"{dataset}: no camera images exported")
    first_folder = images[0].parent
    return [p for p in images if p.parent == first_folder]


def random_homography(width, height, rng):
    """Image-1 pixels to image-2 pixels: the corners moved by up to a fifth of the image, and a rotation."""
    corners = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], dtype=np.float64)
    moved = corners + rng.uniform(-0.2, 0.2, size=(4, 2)) * np.array([width, height])
    angle = rng.uniform(-0.35, 0.35)
    centre = np.array([(width - 1) / 2, (height - 1) / 2])
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    moved = (moved - centre) @ rotation.T + centre
    rows = []
    for (x, y), (u, v) in zip(corners, moved):
        rows.append([x, y, 1, 0, 0, 0, -u * x, -u * y, -u])
        rows.append([0, 0, 0, x, y, 1, -v * x, -v * y, -v])
    h = np.linalg.svd(np.array(rows))[2][-1].reshape(3, 3)
    return h / h[2, 2]


def warp(image, homography):
    """image (H x W grey, uint8) seen through the homography: output pixel p shows input H^-1 p,
    bilinear, pixel centres at integer coordinates, black outside."""
    height, width = image.shape
    inverse = np.linalg.inv(homography)
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    points = inverse @ np.stack([u.ravel(), v.ravel(), np.ones(u.size)])
    x, y = points[0] / points[2], points[1] / points[2]
    grid = torch.tensor(np.stack([2 * x / (width - 1) - 1, 2 * y / (height - 1) - 1], -1), dtype=torch.float32).view(1, height, width, 2)
    source = torch.tensor(image, dtype=torch.float32)[None, None]
    out = F.grid_sample(source, grid, mode="bilinear", padding_mode="zeros", align_corners=True)
    return out[0, 0].round().clamp(0, 255).numpy().astype(np.uint8)


def make_pairs(cli, scenario, work, pairs_per_image, rng, every):
    """(inputs [N, 6], labels [N]) of every pair made from the scenario's images."""
    folder = work / f"pairs_{scenario}"
    folder.mkdir(parents=True, exist_ok=True)
    samples = []
    for index, path in enumerate(camera_images(cli, scenario, work, every)):
        image = np.asarray(Image.open(path).convert("L"))
        for k in range(pairs_per_image):
            stem = folder / f"{index:04d}_{k}"
            csv = Path(f"{stem}.csv")
            if not csv.exists():
                homography = random_homography(image.shape[1], image.shape[0], rng)
                Image.fromarray(image).save(f"{stem}_1.png")
                Image.fromarray(warp(image, homography)).save(f"{stem}_2.png")
                np.savetxt(f"{stem}_H.txt", homography)
                completed = subprocess.run([cli, "features", "match", f"{stem}_1.png", f"{stem}_2.png", "--homography", f"{stem}_H.txt",
                                            "--no-affine-views", "--putative-out", str(csv)], capture_output=True, text=True)
                if completed.returncode != 0:
                    continue  # a view with too little texture: no pair
            data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
            if len(data) >= 8:
                samples.append((data[:, :6].astype(np.float32), data[:, 6].astype(np.float32)))
    return samples


class ContextNorm(nn.Module):
    def forward(self, x):  # [1, C, N]: each channel over the matches
        mean = x.mean(dim=2, keepdim=True)
        variance = ((x - mean) ** 2).mean(dim=2, keepdim=True)
        return (x - mean) / torch.sqrt(variance + 1e-3)


class Block(nn.Module):
    def __init__(self, width):
        super().__init__()
        self.first, self.second = nn.Conv1d(width, width, 1), nn.Conv1d(width, width, 1)
        self.norm1, self.norm2 = nn.BatchNorm1d(width), nn.BatchNorm1d(width)
        self.context = ContextNorm()

    def forward(self, x):
        y = F.relu(self.norm1(self.context(self.first(x))))
        y = F.relu(self.norm2(self.context(self.second(y))))
        return x + y


class Filter(nn.Module):
    def __init__(self):
        super().__init__()
        self.input = nn.Conv1d(6, WIDTH, 1)
        self.blocks = nn.ModuleList([Block(WIDTH) for _ in range(BLOCKS)])
        self.output = nn.Conv1d(WIDTH, 1, 1)

    def forward(self, inputs):  # [N, 6] -> [N] logits
        x = self.input(inputs.t()[None])
        for block in self.blocks:
            x = block(x)
        return self.output(x)[0, 0]


def balanced_loss(logits, labels):
    inliers, outliers = labels > 0.5, labels < 0.5
    loss = 0.0
    if inliers.any():
        loss = loss + F.binary_cross_entropy_with_logits(logits[inliers], labels[inliers])
    if outliers.any():
        loss = loss + F.binary_cross_entropy_with_logits(logits[outliers], labels[outliers])
    return loss


def evaluate(net, samples):
    """Precision and recall of the kept matches (probability >= 0.5) and of the ratio test (0.8)."""
    net.eval()
    counts = {"filter": [0, 0], "ratio": [0, 0]}  # kept, kept and correct
    inliers = 0
    with torch.no_grad():
        for inputs, labels in samples:
            keep = torch.sigmoid(net(torch.tensor(inputs))).numpy() >= 0.5
            ratio = inputs[:, 5] < 0.8
            inliers += labels.sum()
            for name, kept in (("filter", keep), ("ratio", ratio)):
                counts[name][0] += kept.sum()
                counts[name][1] += (kept & (labels > 0.5)).sum()
    return {name: {"precision": float(c / max(k, 1)), "recall": float(c / max(inliers, 1))} for name, (k, c) in counts.items()}


def export(net, path, metadata):
    net.eval()
    layers = {}

    def values(tensor):  # float32 values, written with the 9 digits that give them back exactly
        return [float(f"{v:.9g}") for v in tensor.float().flatten().tolist()]

    def linear(name, conv):
        layers[name + ".weight"] = values(conv.weight.detach()[:, :, 0])
        layers[name + ".bias"] = values(conv.bias.detach())

    def folded(name, norm):
        scale = norm.weight.detach() / torch.sqrt(norm.running_var + norm.eps)
        layers[name.replace("?", "scale")] = values(scale)
        layers[name.replace("?", "shift")] = values(norm.bias.detach() - norm.running_mean * scale)

    linear("input", net.input)
    for b, block in enumerate(net.blocks):
        linear(f"block{b}.first", block.first)
        linear(f"block{b}.second", block.second)
        folded(f"block{b}.?1", block.norm1)
        folded(f"block{b}.?2", block.norm2)
    linear("output", net.output)
    document = {"architecture": "cn-net", "width": WIDTH, "blocks": BLOCKS, "trained": metadata, "layers": layers}
    Path(path).write_text(json.dumps(document, separators=(",", ":")) + "\n")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--cli", required=True)
    parser.add_argument("--work", required=True)
    parser.add_argument("--out", default="models/trained/correspondence_filter.json")
    parser.add_argument("--pairs-per-image", type=int, default=4)
    parser.add_argument("--every", type=int, default=6, help="every N-th camera frame of the 30 s simulations")
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(os.cpu_count() or 1)
    rng = np.random.default_rng(args.seed)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    train = [s for scenario in TRAIN_SCENARIOS for s in make_pairs(args.cli, scenario, work, args.pairs_per_image, rng, args.every)]
    held_back = [s for scenario in HELD_BACK_SCENARIOS for s in make_pairs(args.cli, scenario, work, args.pairs_per_image, rng, args.every)]
    print(f"{len(train)} training pairs ({sum(len(l) for _, l in train)} matches), {len(held_back)} held-back pairs")
    net = Filter()
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-3)
    for epoch in range(args.epochs):
        net.train()
        total = 0.0
        for i in rng.permutation(len(train)):
            inputs, labels = train[i]
            loss = balanced_loss(net(torch.tensor(inputs)), torch.tensor(labels))
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += float(loss)
        if epoch % 5 == 4 or epoch == args.epochs - 1:
            print(f"epoch {epoch + 1}: loss {total / len(train):.4f}, held back {evaluate(net, held_back)}")
    result = evaluate(net, held_back)
    metadata = {"script": "models/trained/train_correspondence_filter.py", "train_scenarios": TRAIN_SCENARIOS,
                "held_back_scenarios": HELD_BACK_SCENARIOS, "pairs": len(train), "epochs": args.epochs, "seed": args.seed,
                "held_back": result}
    export(net, args.out, metadata)
    print(json.dumps({"out": args.out, "held_back": result}))


if __name__ == "__main__":
    main()
