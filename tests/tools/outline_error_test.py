#!/usr/bin/env python3
"""bench/outline_error.py on frames with known errors: a head shifted by two
pixels has all its error in the outline band; a head whose inner colour is off
has it inside; an empty folder, and frames without any error, are refused."""
import os, sys, tempfile

import numpy as np
from matplotlib.image import imsave

import frame_scripts

SCRIPT = sys.argv[1]
BG = frame_scripts.BG


def frame(cx, cy, inner=None):
    y, x = np.mgrid[0:64, 0:64]
    img = np.tile(BG, (64, 64, 1))
    head = (x - cx) ** 2 + (y - cy) ** 2 <= 18 ** 2
    img[head] = [0.8, 0.6, 0.5]
    if inner is not None:
        img[(x - cx) ** 2 + (y - cy) ** 2 <= 10 ** 2] = inner
    return img


def run(folder, *extra):
    return frame_scripts.run(SCRIPT, folder, *extra)


failures = []
with tempfile.TemporaryDirectory() as d:
    shifted, tinted, empty = (os.path.join(d, n) for n in ("shifted", "tinted", "empty"))
    for f in (shifted, tinted, empty):
        os.makedirs(f)
    for k in range(3):
        imsave(os.path.join(shifted, f"truth_{k:05d}.png"), frame(32, 32))
        imsave(os.path.join(shifted, f"avatar_{k:05d}.png"), frame(32, 34))  # two pixels lower
        imsave(os.path.join(tinted, f"truth_{k:05d}.png"), frame(32, 32))
        imsave(os.path.join(tinted, f"avatar_{k:05d}.png"), frame(32, 32, inner=[0.7, 0.5, 0.4]))
    p, r = run(shifted)
    if p.returncode != 0 or r["frames"] != 3 or r["share"]["band_lower"] + r["share"]["band_upper"] < 0.999:
        failures.append(f"shifted: {p.stdout}{p.stderr}")
    elif not r["share"]["band_lower"] > 0.4 or not r["share"]["band_upper"] > 0.4:
        failures.append(f"shifted: a vertical shift errs at the top and the bottom alike: {r['share']}")
    elif r["psnr_without_band_db"] is not None:
        failures.append(f"shifted: nothing is left without the band: {r}")
    p, r = run(tinted)
    if p.returncode != 0 or r["share"]["inside"] < 0.999:
        failures.append(f"tinted: {p.stdout}{p.stderr}")
    elif abs(r["psnr_db"] - r["psnr_without_band_db"]) > 1e-6:
        failures.append(f"tinted: the band holds nothing: {r}")
    same = os.path.join(d, "same")
    os.makedirs(same)
    imsave(os.path.join(same, "truth_00000.png"), frame(32, 32))
    imsave(os.path.join(same, "avatar_00000.png"), frame(32, 32))
    p, _ = run(same)
    if p.returncode == 0 or "no error" not in p.stderr:
        failures.append(f"identical frames: {p.returncode} {p.stderr}")
    p, _ = run(empty)
    if p.returncode == 0 or "no avatar_" not in p.stderr:
        failures.append(f"empty folder accepted: {p.returncode} {p.stderr}")

for f in failures:
    print("FAIL", f)
print("outline_error:", "ok" if not failures else f"{len(failures)} failing")
sys.exit(1 if failures else 0)
