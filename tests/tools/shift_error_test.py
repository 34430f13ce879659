#!/usr/bin/env python3
"""bench/shift_error.py on frames with known shifts: a textured head drawn one
pixel too low in every frame is found one pixel low inside and along both
halves of its outline; drawn where the truth is, at zero; a folder with fewer
frames than blocks is refused."""
import os, sys, tempfile

import numpy as np
from matplotlib.image import imsave

import frame_scripts

SCRIPT = sys.argv[1]
BG = frame_scripts.BG


def frame(cy):
    y, x = np.mgrid[0:64, 0:64].astype(float)
    img = np.tile(BG, (64, 64, 1))
    head = (x - 32) ** 2 + (y - cy) ** 2 <= 20 ** 2
    stripes = 0.5 + 0.3 * np.sin((y - cy) * 0.9) * np.cos(x * 0.4)  # features that move with the head
    img[head] = np.stack([stripes, stripes * 0.8, stripes * 0.6], 2)[head]
    return img


def run(folder, *extra):
    return frame_scripts.run(SCRIPT, folder, *extra)


failures = []
with tempfile.TemporaryDirectory() as d:
    low, same, few = (os.path.join(d, n) for n in ("low", "same", "few"))
    for f in (low, same, few):
        os.makedirs(f)
    for k in range(4):
        imsave(os.path.join(low, f"truth_{k:05d}.png"), frame(32))
        imsave(os.path.join(low, f"avatar_{k:05d}.png"), frame(33))  # one pixel lower
        imsave(os.path.join(same, f"truth_{k:05d}.png"), frame(32))
        imsave(os.path.join(same, f"avatar_{k:05d}.png"), frame(32))
    imsave(os.path.join(few, "truth_00000.png"), frame(32))
    imsave(os.path.join(few, "avatar_00000.png"), frame(32))
    p, r = run(low, "--blocks", "2")
    if p.returncode != 0:
        failures.append(f"low: {p.stdout}{p.stderr}")
    else:
        for k in ("inside", "outline_upper", "outline_lower"):
            if r["best_shift_px"][k] != [-1.0, -1.0]:
                failures.append(f"low: {k} {r['best_shift_px'][k]}, expected -1 in both blocks")
    p, r = run(same, "--blocks", "2")
    if p.returncode != 0 or any(v != 0 for v in r["mean_px"].values()):
        failures.append(f"same: {p.stdout}{p.stderr}")
    p, _ = run(few, "--blocks", "2")
    if p.returncode == 0 or "fewer than --blocks" not in p.stderr:
        failures.append(f"too few frames: {p.returncode} {p.stderr}")
if failures:
    print("\n".join(failures))
    sys.exit(1)
print("shift_error: a head drawn a pixel low is found there; none found where none is; too few frames refused")
