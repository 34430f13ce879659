#!/usr/bin/env python3
"""Is a clip's picture smeared along the head's motion (the camera's exposure)?

For each frame of a prepared dataset, the head's image motion (the fitted head's
vertices projected through the crop's camera, the median displacement between
the frames either side, halved) and the picture's gradient energy inside the
head mask along that motion and across it. A frame smeared by its motion has
less energy along it than a still frame has along the same direction: the
log ratio (along / across) minus its median over the still frames (under 0.5
pixel a frame) is printed per band of speed. Then the same measure on still
frames smeared on purpose by a box of known length, to read the bands' figures
as a smear in pixels (bilinear sampling alone costs some of it).

  headcast-rec export DS/params.hcrec --out params.npz
  bench/motion_smear.py DS params.npz ict.npz      (ict.npz: the head model the dataset was fitted with)
"""
import json
import sys

import numpy as np
from PIL import Image
from scipy import ndimage
from scipy.spatial.transform import Rotation


def projector(dataset, params, model):
    camera = json.load(open(dataset + "/dataset.json"))["intrinsics"]
    fx, fy, cx, cy = next(iter(camera.values()))
    keep = np.arange(0, model["v_template"].shape[0], 7)
    shape = params["shape"].astype(float)
    base = (model["v_template"] + model["shapedirs"][:, :, : len(shape)] @ shape)[keep]
    directions = model["expressiondirs"][keep]

    def project(i):
        v = base + directions @ params["expression"][i].astype(float)
        v = Rotation.from_rotvec(params["neck"][i].astype(float)).apply(v)
        x = Rotation.from_rotvec(params["cam_rotation"][i].astype(float)).apply(v) + params["cam_translation"][i]
        return np.c_[fx * x[:, 0] / x[:, 2] + cx, fy * x[:, 1] / x[:, 2] + cy]

    return project, int(next(iter(camera.keys())))


def log_ratio(gx, gy, u):
    along = ((gx * u[0] + gy * u[1]) ** 2).mean()
    across = ((-gx * u[1] + gy * u[0]) ** 2).mean()
    return np.log(along / across)


def smear(image, length, u):
    taps = np.linspace(-length / 2, length / 2, max(2, int(np.ceil(2 * length)) + 1))
    yy, xx = np.mgrid[0 : image.shape[0], 0 : image.shape[1]].astype(float)
    return np.mean([ndimage.map_coordinates(image, [yy + s * u[1], xx + s * u[0]], order=1, mode="nearest")
                    for s in taps], axis=0)


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    dataset, params_path, model_path = sys.argv[1:]
    params, model = np.load(params_path), np.load(model_path)
    project, size = projector(dataset, params, model)
    n = len(params["sequence"])
    points = [project(i) for i in range(n)]
    pictures, velocity = [], []
    for i in range(n):
        grey = np.asarray(Image.open(f"{dataset}/{size}/images/{i:05d}.png").convert("L"), float)
        mask = ndimage.binary_erosion(np.asarray(Image.open(f"{dataset}/{size}/masks/{i:05d}.png")) > 127,
                                      iterations=3)
        pictures.append((grey, mask))
        before, after = points[max(i - 1, 0)], points[min(i + 1, n - 1)]
        inside = np.all((points[i] > 0) & (points[i] < size), axis=1)
        velocity.append(np.median((after - before)[inside] / 2, axis=0))
    velocity = np.array(velocity)
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    grads = [(ndimage.sobel(g, 1)[m], ndimage.sobel(g, 0)[m]) for g, m in pictures]
    still = np.where(speed < 0.5)[0]
    print(f"{dataset}: {n} frames; head speed median {np.median(speed):.2f}, 90th percentile "
          f"{np.percentile(speed, 90):.2f} px/frame; {len(still)} still (< 0.5 px/frame)")
    print("| speed (px/frame) | frames | log(along / across) against still frames: mean (sd) |")
    print("|---|---|---|")
    for lo, hi in [(0.5, 1), (1, 2), (2, 3), (3, np.inf)]:
        band = np.where((speed >= lo) & (speed < hi))[0]
        if len(band) == 0:
            continue
        change = []
        for i in band:
            u = velocity[i] / speed[i]
            change.append(log_ratio(*grads[i], u) - np.median([log_ratio(*grads[j], u) for j in still[::3]]))
        print(f"| {lo:g}–{hi:g} | {len(band)} | {np.mean(change):+.3f} ({np.std(change):.3f}) |")
    print("\nStill frames smeared on purpose (every 4th still frame, along x and along y):")
    print("| box length (px) | log(along / across) change |")
    print("|---|---|")
    for length in [0.5, 1, 2, 3]:
        change = []
        for i in still[::4]:
            grey, mask = pictures[i]
            for u in [(1, 0), (0, 1)]:
                smeared = smear(grey, length, u)
                change.append(log_ratio(ndimage.sobel(smeared, 1)[mask], ndimage.sobel(smeared, 0)[mask], u) -
                              log_ratio(*grads[i], u))
        print(f"| {length:g} | {np.mean(change):+.3f} |")
    print(f"\nreproduce: bench/motion_smear.py {dataset} {params_path} {model_path}")


if __name__ == "__main__":
    main()
