#!/usr/bin/env python3
"""headcast against a classic video codec on the same footage.

The footage is a dataset's test frames as the avatar is scored on them (the
head on a flat background, `headcast-train eval --write-frames`). x264
(ffmpeg, zerolatency, same size and 30 fps) encodes them at several bitrates;
each decoded video is scored against the frames with the same PSNR and SSIM
(11x11 Gaussian, sigma 1.5) the trainer uses. headcast's point is the avatar's
score on the same frames at the kbit/s headcast measured on the wire.

The avatar's picture does not depend on the link (the same parameters arrive,
later or sooner), so headcast has one quality at each measured link rate.

Usage: x264_compare.py --frames DIR --headcast KBPS:LABEL [--headcast ...] [--kbps 16,32,...] --out OUT.json [--plot OUT.png]
"""
import argparse, glob, json, os, subprocess, tempfile

import numpy as np
from scipy.ndimage import gaussian_filter


def read_video(path, w, h):
    raw = subprocess.run(["ffmpeg", "-loglevel", "error", "-i", path, "-f", "rawvideo", "-pix_fmt", "rgb24", "-"],
                         check=True, capture_output=True).stdout
    return np.frombuffer(raw, np.uint8).reshape(-1, h, w, 3).astype(np.float64) / 255


def read_frames(pattern):
    first = sorted(glob.glob(pattern.replace("%05d", "*")))[0]
    probe = subprocess.run(["ffprobe", "-v", "error", "-show_entries", "stream=width,height", "-of", "csv=p=0", first],
                           check=True, capture_output=True, text=True).stdout.strip().split(",")
    w, h = int(probe[0]), int(probe[1])
    raw = subprocess.run(["ffmpeg", "-loglevel", "error", "-i", pattern, "-f", "rawvideo", "-pix_fmt", "rgb24", "-"],
                         check=True, capture_output=True).stdout
    return np.frombuffer(raw, np.uint8).reshape(-1, h, w, 3).astype(np.float64) / 255, w, h


def psnr(a, b):
    return 10 * np.log10(1 / max(np.mean((a - b) ** 2), 1e-12))


def ssim(a, b):
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    f = lambda x: gaussian_filter(x, sigma=(1.5, 1.5, 0), truncate=3.5)  # 11x11 window
    ma, mb = f(a), f(b)
    va, vb, cov = f(a * a) - ma * ma, f(b * b) - mb * mb, f(a * b) - ma * mb
    return float(np.mean(((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))))


def score(truth, test):
    n = min(len(truth), len(test))
    return (float(np.mean([psnr(truth[i], test[i]) for i in range(n)])),
            float(np.mean([ssim(truth[i], test[i]) for i in range(n)])))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", required=True, help="folder with truth_NNNNN.png and avatar_NNNNN.png")
    ap.add_argument("--headcast", action="append", required=True,
                    help="KBPS:LABEL, headcast's uplink on the wire at 30 fps in some setting (repeatable)")
    ap.add_argument("--kbps", default="8,16,32,64,128,256,512")
    ap.add_argument("--out", required=True)
    ap.add_argument("--plot")
    a = ap.parse_args()
    truth, w, h = read_frames(os.path.join(a.frames, "truth_%05d.png"))
    avatar, _, _ = read_frames(os.path.join(a.frames, "avatar_%05d.png"))
    points = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in [float(x) for x in a.kbps.split(",")]:
            video = os.path.join(tmp, f"x264_{k:g}.mp4")
            subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-framerate", "30", "-i",
                            os.path.join(a.frames, "truth_%05d.png"), "-c:v", "libx264", "-preset", "veryfast",
                            "-tune", "zerolatency", "-b:v", f"{k:g}k", "-maxrate", f"{k:g}k",
                            "-bufsize", f"{k / 2:g}k", "-pix_fmt", "yuv420p", video], check=True)
            frames = len(truth)
            kbps = 8e-3 * os.path.getsize(video) / (frames / 30)
            p, s = score(truth, read_video(video, w, h))
            points.append({"target_kbps": k, "kbps": kbps, "psnr_db": p, "ssim": s})
            print(f"x264 {k:g} kbit/s target: {kbps:.1f} kbit/s, PSNR {p:.2f} dB, SSIM {s:.3f}")
    hp, hs = score(truth, avatar)
    headcast = [{"kbps_on_wire": float(x.split(":", 1)[0]), "setting": x.split(":", 1)[1] if ":" in x else "",
                 "psnr_db": hp, "ssim": hs} for x in a.headcast]
    result = {"frames": len(truth), "size": [w, h], "fps": 30,
              "x264": points,
              "x264_settings": "ffmpeg libx264 -preset veryfast -tune zerolatency, CBR-ish (maxrate = bitrate), yuv420p; "
                               "kbit/s from the file size (container overhead included)",
              "headcast": headcast,
              "scoring": "PSNR and SSIM (11x11 Gaussian, sigma 1.5) on RGB in [0,1], mean over frames"}
    json.dump(result, open(a.out, "w"), indent=2)
    for point in headcast:
        print(f"headcast ({point['setting']}): {point['kbps_on_wire']:.1f} kbit/s on the wire, PSNR {hp:.2f} dB, "
              f"SSIM {hs:.3f}")
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
        for ax, key, label in ((ax1, "psnr_db", "PSNR (dB)"), (ax2, "ssim", "SSIM")):
            ax.plot([p["kbps"] for p in points], [p[key] for p in points], "o-", label="x264 zerolatency")
            ax.plot([p["kbps_on_wire"] for p in headcast], [p[key] for p in headcast], "r*", markersize=14,
                    label="headcast (avatar)")
            ax.set_xscale("log")
            ax.set_xlabel("kbit/s")
            ax.set_ylabel(label)
            ax.grid(True, alpha=0.3)
            ax.legend()
        fig.suptitle(f"rate-quality, {len(truth)} test frames at {w}x{h}, 30 fps")
        fig.tight_layout()
        fig.savefig(a.plot, dpi=100)


if __name__ == "__main__":
    main()
