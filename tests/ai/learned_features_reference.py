"""Independent PyTorch run of ALIKED / ALIKE weights, the reference of tests/ai/learned_features_test.cpp.

The networks are torch.nn modules loaded with load_state_dict(strict=True) (every tensor of the
file used, none missing), deformable convolutions by torchvision.ops.deform_conv2d, detection as
the upstream DKD. Writes, for one image, the score map and the keypoints, scores and descriptors
as raw little-endian float32 files next to a JSON header.

Usage: learned_features_reference.py MODEL WEIGHTS.pth IMAGE OUT_PREFIX [--threshold T] [--max N]
"""
import argparse
import json
import math

import numpy as np
import torch
import torch.nn.functional as F
import torchvision
from PIL import Image
from torch import nn

ALIKED = {"aliked-t16": (8, 16, 32, 64, 64, 16), "aliked-n16": (16, 32, 64, 128, 128, 16),
          "aliked-n16rot": (16, 32, 64, 128, 128, 16), "aliked-n32": (16, 32, 64, 128, 128, 32)}
ALIKE = {"alike-t": (8, 16, 32, 64, 64, True), "alike-s": (8, 16, 48, 96, 96, True),
         "alike-n": (16, 32, 64, 128, 128, True), "alike-l": (32, 64, 128, 128, 128, False)}


def conv3(i, o):
    return nn.Conv2d(i, o, 3, padding=1, bias=False)


def conv1(i, o):
    return nn.Conv2d(i, o, 1, bias=False)


class Deformable(nn.Module):
    def __init__(self, i, o):
        super().__init__()
        self.offset_conv = nn.Conv2d(i, 18, 3, padding=1, bias=True)
        self.regular_conv = nn.Conv2d(i, o, 3, padding=1, bias=False)

    def forward(self, x):
        limit = max(x.shape[2:]) / 4.0
        offset = self.offset_conv(x).clamp(-limit, limit)
        return torchvision.ops.deform_conv2d(x, offset, self.regular_conv.weight, None, padding=(1, 1))


class Block(nn.Module):
    """Two 3x3 convolutions with batch norm; residual=True adds a 1x1 shortcut (ResNet BasicBlock)."""

    def __init__(self, i, o, gate, residual, deformable=False):
        super().__init__()
        make = (lambda a, b: Deformable(a, b)) if deformable else conv3
        self.conv1, self.bn1 = make(i, o), nn.BatchNorm2d(o)
        self.conv2, self.bn2 = make(o, o), nn.BatchNorm2d(o)
        self.downsample = nn.Conv2d(i, o, 1) if residual else None
        self.gate = gate

    def forward(self, x):
        y = self.gate(self.bn1(self.conv1(x)))
        y = self.bn2(self.conv2(y))
        return self.gate(y + self.downsample(x)) if self.downsample is not None else self.gate(y)


class Encoder(nn.Module):
    def __init__(self, c1, c2, c3, c4, dim, gate, pool, deformable):
        super().__init__()
        self.gate, self.pool = gate, pool
        self.block1 = Block(3, c1, gate, False)
        self.block2 = Block(c1, c2, gate, True)
        self.block3 = Block(c2, c3, gate, True, deformable)
        self.block4 = Block(c3, c4, gate, True, deformable)
        self.conv1, self.conv2, self.conv3, self.conv4 = conv1(c1, dim // 4), conv1(c2, dim // 4), conv1(c3, dim // 4), conv1(c4, dim // 4)

    def aggregate(self, image):
        x1 = self.block1(image)
        x2 = self.block2(self.pool(x1, 2))
        x3 = self.block3(self.pool(x2, 4))
        x4 = self.block4(self.pool(x3, 4))
        size = image.shape[2:]
        up = lambda x: F.interpolate(x, size=size, mode="bilinear", align_corners=True)
        return torch.cat([self.gate(self.conv1(x1)), up(self.gate(self.conv2(x2))), up(self.gate(self.conv3(x3))),
                          up(self.gate(self.conv4(x4)))], 1)


class Aliked(Encoder):
    def __init__(self, c1, c2, c3, c4, dim, positions):
        super().__init__(c1, c2, c3, c4, dim, nn.SELU(), lambda x, k: F.avg_pool2d(x, k, k), True)
        self.score_head = nn.Sequential(conv1(dim, 8), nn.SELU(), conv3(8, 4), nn.SELU(), conv3(4, 4), nn.SELU(), conv3(4, 1))
        self.desc_head = nn.Module()
        self.desc_head.offset_conv = nn.Sequential(nn.Conv2d(dim, 2 * positions, 3), nn.SELU(), nn.Conv2d(2 * positions, 2 * positions, 1))
        self.desc_head.sf_conv = conv1(dim, dim)
        self.desc_head.agg_weights = nn.Parameter(torch.zeros(positions, dim, dim))
        self.positions = positions

    def dense(self, image):
        h, w = image.shape[2:]
        ph, pw = (32 - h % 32) % 32, (32 - w % 32) % 32
        pad = [pw // 2, pw - pw // 2, ph // 2, ph - ph // 2]
        x = self.aggregate(F.pad(image, pad, mode="replicate"))
        score = torch.sigmoid(self.score_head(x))
        crop = lambda t: t[:, :, pad[2]:pad[2] + h, pad[0]:pad[0] + w]
        return crop(score), crop(F.normalize(x, dim=1))

    def describe(self, features, keypoints, subpixel):
        c, h, w = features.shape[1:]
        wh = torch.tensor([[w - 1, h - 1]], dtype=torch.float32)
        pixels = (keypoints / 2 + 0.5) * wh
        integer = pixels.long()
        padded = F.pad(features[0], (1, 1, 1, 1))
        patches = torch.stack([padded[:, y:y + 3, x:x + 3] for x, y in integer.tolist()])
        limit = max(h, w) / 4.0
        offset = self.desc_head.offset_conv(patches).clamp(-limit, limit)[:, :, 0, 0]
        offset = offset.view(len(keypoints), 2, self.positions).permute(0, 2, 1)
        grid = (2.0 * (pixels[:, None] + offset) / wh[None] - 1).reshape(1, -1, 1, 2)
        sampled = F.grid_sample(features, grid, mode="bilinear", align_corners=True)
        sampled = sampled.reshape(c, len(keypoints), self.positions, 1).permute(1, 0, 2, 3)
        sampled = F.selu(self.desc_head.sf_conv(sampled)).squeeze(-1)
        return F.normalize(torch.einsum("ncp,pcd->nd", sampled, self.desc_head.agg_weights), dim=1)


class Alike(Encoder):
    def __init__(self, c1, c2, c3, c4, dim, single_head):
        super().__init__(c1, c2, c3, c4, dim, nn.ReLU(), lambda x, k: F.max_pool2d(x, k, k), False)
        self.convhead1 = None if single_head else conv1(dim, dim)
        self.convhead2 = conv1(dim, dim + 1)
        self.dim = dim

    def dense(self, image):
        h, w = image.shape[2:]
        x = self.aggregate(F.pad(image, (0, (32 - w % 32) % 32, 0, (32 - h % 32) % 32)))
        if self.convhead1 is not None:
            x = F.relu(self.convhead1(x))
        x = self.convhead2(x)[:, :, :h, :w]
        return torch.sigmoid(x[:, -1:]), F.normalize(x[:, :-1], dim=1)

    def describe(self, descriptor_map, keypoints, subpixel):
        c, h, w = descriptor_map.shape[1:]
        if subpixel:
            d = F.grid_sample(descriptor_map, keypoints.view(1, 1, -1, 2), mode="bilinear", align_corners=True)[0, :, 0, :]
        else:
            p = ((keypoints + 1) / 2 * torch.tensor([[w - 1, h - 1]])).long()
            d = descriptor_map[0, :, p[:, 1], p[:, 0]]
        return F.normalize(d, dim=0).t()


def simple_nms(scores, radius):
    pool = lambda x: F.max_pool2d(x, 2 * radius + 1, 1, radius)
    zeros = torch.zeros_like(scores)
    mask = scores == pool(scores)
    for _ in range(2):
        suppressed = pool(mask.float()) > 0
        kept = torch.where(suppressed, zeros, scores)
        mask = mask | ((kept == pool(kept)) & ~suppressed)
    return torch.where(mask, scores, zeros)


def detect(scores, radius, threshold, limit, subpixel):
    _, _, h, w = scores.shape
    nms = simple_nms(scores, radius)
    nms[:, :, :radius + 1] = 0
    nms[:, :, :, :radius + 1] = 0
    nms[:, :, h - radius:] = 0
    nms[:, :, :, w - radius:] = 0
    flat = nms.reshape(-1)
    if threshold > 0:
        mask = flat > threshold
        if mask.sum() == 0:
            mask = flat > scores.mean()
        indices = mask.nonzero()[:, 0]
        if len(indices) > limit:
            order = scores.reshape(-1)[indices].sort(descending=True)[1]
            indices = indices[order[:limit]]
    else:
        indices = flat.topk(limit).indices
    xy = torch.stack([indices % w, torch.div(indices, w, rounding_mode="floor")], 1).float()
    if subpixel:
        k = 2 * radius + 1
        patches = F.unfold(scores, k, padding=radius)[0].t()[indices]
        weights = ((patches - patches.max(1, keepdim=True).values) / 0.1).exp()
        r = torch.linspace(-radius, radius, k)
        grid = torch.stack(torch.meshgrid(r, r, indexing="ij")).view(2, -1).t()[:, [1, 0]]
        xy = xy + weights @ grid / weights.sum(1, keepdim=True)
    normalized = xy / torch.tensor([w - 1, h - 1]) * 2 - 1
    score = F.grid_sample(scores, normalized.view(1, 1, -1, 2), mode="bilinear", align_corners=True)[0, 0, 0]
    return normalized, score


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("model")
    parser.add_argument("weights")
    parser.add_argument("image")
    parser.add_argument("out")
    parser.add_argument("--threshold", type=float, default=0.2)
    parser.add_argument("--max", type=int, default=2000)
    parser.add_argument("--no-subpixel", action="store_true")
    args = parser.parse_args()
    net = Aliked(*ALIKED[args.model]) if args.model in ALIKED else Alike(*ALIKE[args.model])
    state = torch.load(args.weights, map_location="cpu")
    net.load_state_dict(state, strict=True)
    net.eval()
    torch.set_num_threads(2)
    rgb = np.asarray(Image.open(args.image).convert("RGB"), dtype=np.float32) / 255.0
    image = torch.from_numpy(rgb).permute(2, 0, 1)[None].contiguous()
    subpixel = not args.no_subpixel
    with torch.no_grad():
        score_map, features = net.dense(image)
        keypoints, scores = detect(score_map, 2, args.threshold, args.max, subpixel)
        descriptors = net.describe(features, keypoints, subpixel)
    h, w = score_map.shape[2:]
    pixels = (keypoints + 1) / 2 * torch.tensor([[w - 1, h - 1]])
    for name, tensor in (("score_map", score_map[0, 0]), ("keypoints", pixels), ("scores", scores), ("descriptors", descriptors)):
        tensor.contiguous().numpy().astype("<f4").tofile(f"{args.out}.{name}.f32")
    print(json.dumps({"height": h, "width": w, "keypoints": len(keypoints), "descriptor_size": descriptors.shape[1]}))


if __name__ == "__main__":
    main()
