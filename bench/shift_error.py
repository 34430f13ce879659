#!/usr/bin/env python3
"""How far an avatar's picture sits from the truth's: per frame, the vertical
shift of the avatar (bilinear, in quarter pixels) that leaves the least squared
error inside the head, along the outline's upper half and along its lower half;
averaged over blocks of consecutive frames.

  bench/shift_error.py FRAMES [--blocks N] [--max-shift PX] [--json OUT.json]

FRAMES: the folder `headcast-train eval --write-frames` writes (truth_N.png,
avatar_N.png). A negative shift moves the avatar up: it was drawn too low. The
truth's head is every pixel not of the background colour (its corner's);
"inside" is the head eroded by 6 px, the outline band +-3 px. A shift inside
that the training frames do not show but the held-out ones do is what the
networks draw differently on unseen frames (wide-open lids drawn ordinary
read as a face drawn too low), not the fit's placement, which both share."""
import argparse, json, sys

import numpy as np
from scipy import ndimage

from eval_frames import avatar_paths, head_of, load_pair


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("frames")
    ap.add_argument("--blocks", type=int, default=6, help="blocks of consecutive frames to average over")
    ap.add_argument("--max-shift", type=float, default=1.5, help="largest shift tried, pixels")
    ap.add_argument("--json")
    a = ap.parse_args()
    avatars = avatar_paths(a.frames, "shift_error")
    if len(avatars) < a.blocks:
        sys.exit(f"shift_error: {len(avatars)} avatar_*.png in {a.frames}, fewer than --blocks {a.blocks}")
    shifts = np.arange(-a.max_shift, a.max_shift + 1e-9, 0.25)
    best = {"inside": [], "outline_upper": [], "outline_lower": []}
    for path in avatars:
        avatar, truth = load_pair(path, "shift_error")
        head = ndimage.binary_fill_holes(ndimage.binary_closing(head_of(truth), iterations=2))
        band = ndimage.binary_dilation(head, iterations=3) & ~ndimage.binary_erosion(head, iterations=3)
        rows = np.nonzero(head.any(1))[0]
        upper = np.zeros_like(head)
        if rows.size:
            upper[:(rows.min() + rows.max()) // 2] = True
        regions = {"inside": ndimage.binary_erosion(head, iterations=6), "outline_upper": band & upper,
                   "outline_lower": band & ~upper}
        errors = {k: [] for k in regions}
        for dy in shifts:
            moved = ndimage.shift(avatar, (dy, 0, 0), order=1, mode="nearest") if dy else avatar
            err = ((moved - truth) ** 2).sum(2)
            for k, r in regions.items():
                errors[k].append(err[r].mean() if r.any() else 0.0)
        for k in regions:
            best[k].append(float(shifts[int(np.argmin(errors[k]))]))
    n = len(avatars) // a.blocks
    result = {"frames": len(avatars), "block_frames": n,
              "best_shift_px": {k: [round(float(np.mean(v[i * n:(i + 1) * n])), 3) for i in range(a.blocks)]
                                for k, v in best.items()},
              "mean_px": {k: round(float(np.mean(v)), 3) for k, v in best.items()}}
    print(f"{len(avatars)} frames, best vertical shift of the avatar (px; negative: drawn too low), "
          f"mean over blocks of {n}:")
    for k, v in result["best_shift_px"].items():
        print(f"  {k:14s} {' '.join(f'{x:+.2f}' for x in v)}   all {result['mean_px'][k]:+.2f}")
    print(f"reproduce: bench/shift_error.py FRAMES --blocks {a.blocks} --max-shift {a.max_shift}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
