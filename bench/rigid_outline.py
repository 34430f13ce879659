#!/usr/bin/env python3
"""How steadily a fit holds the head against its hair: per frame, the distance
from a skull point (the top of the identity's head, projected with the fitted
pose) up to the top of the head mask in that column, in millimetres at the
head's distance. The hair does not move on the skull, so what this distance
does from frame to frame is mostly the fit sliding the head (and GrabCut's
outline); its spread compares tracker settings in a minute, without training
an avatar (how well it follows an avatar's misplacement: the benchmark
report). Long hair that moves, and large pitch changes (the outline is a
silhouette, not a point), add to it.

  bench/rigid_outline.py DATASET --head-model MODEL.npz [--frames A:B] [--bin DIR]

DATASET: a `headcast-train prep` folder (params.hcrec, full_masks/); MODEL.npz:
the head model it was prepared with. Prints the mean offset, its spread, the
frame-to-frame spread and the spread about a 15-frame running median."""
import argparse, os, subprocess, sys, tempfile

import numpy as np
from matplotlib.image import imread
from scipy.ndimage import median_filter


def rotation(w):
    angle = np.linalg.norm(w)
    if angle < 1e-12:
        return np.eye(3)
    k = w / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset")
    ap.add_argument("--head-model", required=True)
    ap.add_argument("--frames", help="A:B, positions in the dataset (default: all)")
    ap.add_argument("--bin", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build", "bin"))
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        npz = os.path.join(tmp, "params.npz")
        r = subprocess.run([os.path.join(a.bin, "headcast-rec"), "export", os.path.join(a.dataset, "params.hcrec"),
                            "--format", "npz", "--out", npz], capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"rigid_outline: headcast-rec export failed:\n{r.stderr}")
        p = dict(np.load(npz))
    model = np.load(a.head_model, allow_pickle=True)
    shape = p["shape"]
    v = model["v_template"] + model["shapedirs"][:, :, :len(shape)] @ shape
    top = v[np.argmax(v[:, 1] - 5 * np.abs(v[:, 0]))]  # the crown, near the middle
    fx, fy, cx, cy = p["intrinsics"][:4]
    n = len(p["cam_rotation"])
    first, last = (int(x) for x in a.frames.split(":")) if a.frames else (0, n)
    offsets = []
    for i in range(first, min(last, n)):
        x = rotation(p["cam_rotation"][i]) @ top + p["cam_translation"][i]
        u, v_px = fx * x[0] / x[2] + cx, fy * x[1] / x[2] + cy
        mask = imread(os.path.join(a.dataset, "full_masks", f"{i:05d}.png"))
        mask = (mask if mask.ndim == 2 else mask[..., 0]) > 0.5
        column = int(round(u))
        rows = np.where(mask[:, max(0, column - 3):column + 4].any(1))[0]
        if len(rows):
            offsets.append((rows[0] - v_px) / (fy / x[2]) * 1e3)
    if len(offsets) < 16:
        sys.exit(f"rigid_outline: only {len(offsets)} frames with a mask above the head")
    d = np.array(offsets)
    steady = d - median_filter(d, 15, mode="nearest")
    print(f"{len(d)} frames: mask top {-d.mean():+.1f} mm from the crown point (+: above), spread {d.std():.2f} mm, "
          f"frame to frame {np.diff(d).std() / np.sqrt(2):.2f} mm, about the running median {steady.std():.2f} mm")
    print(f"reproduce: bench/rigid_outline.py DATASET --head-model MODEL.npz" + (f" --frames {a.frames}" if a.frames else ""))


if __name__ == "__main__":
    main()
