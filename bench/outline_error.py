#!/usr/bin/env python3
"""Where an avatar's squared error lies: within a few pixels of the true mask's
outline (its lower and upper half), inside the head, or on the background.

  bench/outline_error.py FRAMES [--band PX] [--json OUT.json]

FRAMES: the folder `headcast-train eval --write-frames` writes (truth_N.png,
avatar_N.png). The truth's head is every pixel not of the background colour
(its corner's). Prints each part's share of the summed squared error and the
PSNR of the mean squared error with and without the outline band."""
import argparse, json, math, sys

import numpy as np
from scipy import ndimage

from eval_frames import avatar_paths, head_of, load_pair


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("frames")
    ap.add_argument("--band", type=int, default=3, help="pixels either side of the outline")
    ap.add_argument("--json")
    a = ap.parse_args()
    avatars = avatar_paths(a.frames, "outline_error")
    parts = dict(band_lower=0.0, band_upper=0.0, inside=0.0, outside=0.0)
    for path in avatars:
        avatar, truth = load_pair(path, "outline_error")
        head = head_of(truth)
        band = ndimage.binary_dilation(head, iterations=a.band) & ~ndimage.binary_erosion(head, iterations=a.band)
        rows = np.nonzero(head)[0]
        lower = np.zeros_like(head)
        if rows.size:
            lower[(rows.min() + rows.max()) // 2:] = True
        err = ((avatar - truth) ** 2).mean(2) / (len(avatars) * head.size)  # a share of the mean over all
        parts["band_lower"] += err[band & lower].sum()
        parts["band_upper"] += err[band & ~lower].sum()
        parts["inside"] += err[head & ~band].sum()
        parts["outside"] += err[~head & ~band].sum()
    mse = sum(parts.values())
    band = parts["band_lower"] + parts["band_upper"]
    if not mse > 0:
        sys.exit(f"outline_error: the avatar frames in {a.frames} equal their truths: no error to place")
    rest = mse - band
    result = {"frames": len(avatars), "band_px": a.band,
              "share": {k: v / mse for k, v in parts.items()},
              "psnr_db": -10 * math.log10(mse),
              "psnr_without_band_db": -10 * math.log10(rest) if rest > 1e-15 else None}  # None: all in the band
    print(f"{len(avatars)} frames; share of the squared error: outline band (±{a.band} px) lower "
          f"{result['share']['band_lower']:.2f}, upper {result['share']['band_upper']:.2f}; inside "
          f"{result['share']['inside']:.2f}; background {result['share']['outside']:.2f}; PSNR of the mean "
          f"{result['psnr_db']:.2f} dB, " + (f"{result['psnr_without_band_db']:.2f} dB" if result["psnr_without_band_db"]
                                              else "no error") + " without the band")
    print(f"reproduce: bench/outline_error.py FRAMES --band {a.band}")
    if a.json:
        json.dump(result, open(a.json, "w"), indent=2)


if __name__ == "__main__":
    main()
