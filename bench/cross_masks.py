#!/usr/bin/env python3
"""An avatar's held-out frames against the test targets of another prep of the same clip.

A dataset's masks are cut with the fitted head (jaw line, silhouette bound), so a
tracker change moves the targets as well as the avatar. This measures the avatar
written by `headcast-train eval --write-frames` (EVAL/frames) against its own
dataset's targets and against OTHER_DATASET's (same clip, same split), by the
mean of the frames' PSNR, and how much the two preps' test masks overlap.

  bench/cross_masks.py DATASET EVAL OTHER_DATASET [--resolution 256]
"""
import argparse
import json
import os
import sys

import numpy as np
from PIL import Image


def load(path, mode="RGB"):
    return np.array(Image.open(path).convert(mode)).astype(np.float64)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset")
    ap.add_argument("eval")
    ap.add_argument("other")
    ap.add_argument("--resolution", type=int, default=256)
    a = ap.parse_args()
    split = json.load(open(os.path.join(a.dataset, "dataset.json")))["split"]
    other_split = json.load(open(os.path.join(a.other, "dataset.json")))["split"]
    test = json.load(open(os.path.join(a.dataset, "dataset.json")))["frame_numbers"][-split["test"]:]
    other_test = json.load(open(os.path.join(a.other, "dataset.json")))["frame_numbers"][-other_split["test"]:]
    if test != other_test:
        sys.exit("cross_masks: the two datasets' test frames differ")
    frames = os.path.join(a.eval, "frames")
    background = load(os.path.join(frames, "truth_00000.png"))[0, 0]  # the renders' colour
    own, other, iou = [], [], []
    for i, n in enumerate(test):
        name = f"{n:05d}.png"
        avatar = load(os.path.join(frames, f"avatar_{i:05d}.png"))
        psnr = []
        masks = []
        for ds in (a.dataset, a.other):
            image = load(os.path.join(ds, str(a.resolution), "images", name))
            mask = load(os.path.join(ds, str(a.resolution), "masks", name), "L") > 127
            masks.append(mask)
            target = np.where(mask[..., None], image, background)
            psnr.append(10 * np.log10(255.0**2 / np.mean((avatar - target) ** 2)))
        own.append(psnr[0])
        other.append(psnr[1])
        iou.append((masks[0] & masks[1]).sum() / max(1, (masks[0] | masks[1]).sum()))
    print(f"{len(test)} test frames; test masks' IoU between the preps: mean {np.mean(iou):.4f}, min {np.min(iou):.4f}")
    print(f"avatar against its own dataset's targets: {np.mean(own):.3f} dB; against the other's: {np.mean(other):.3f} dB")
    print("reproduce: bench/cross_masks.py DATASET EVAL OTHER_DATASET")


if __name__ == "__main__":
    main()
