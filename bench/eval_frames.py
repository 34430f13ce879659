"""The frames `headcast-train eval --write-frames` writes (truth_N.png,
avatar_N.png), for the benchmark's scripts that look at where an avatar errs."""
import glob, os, sys

import numpy as np
from matplotlib.image import imread


def avatar_paths(folder, tool):
    """The avatar frames in `folder`, sorted; exits naming `tool` when there are none."""
    paths = sorted(glob.glob(os.path.join(folder, "avatar_*.png")))
    if not paths:
        sys.exit(f"{tool}: no avatar_*.png in {folder} (headcast-train eval --write-frames)")
    return paths


def load_pair(path, tool):
    """An avatar frame and its truth as RGB arrays in 0..1; exits naming `tool` when their sizes differ."""
    truth_path = os.path.join(os.path.dirname(path), os.path.basename(path).replace("avatar_", "truth_"))
    avatar, truth = imread(path)[..., :3].astype(np.float64), imread(truth_path)[..., :3].astype(np.float64)
    if avatar.shape != truth.shape:
        sys.exit(f"{tool}: {path} and {truth_path} differ in size")
    return avatar, truth


def head_of(truth):
    """The truth's head: every pixel not of the background colour (its corner's)."""
    return np.abs(truth - truth[0, 0]).sum(2) > 0.02
