#!/usr/bin/env python3
"""Compares a headcast-track recording with the truth.json written by
`headcast-headmodel render-rgbd`: per-frame head position and rotation errors,
and the identity. Prints JSON; exits 1 when --max-translation-mm is exceeded.
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
import hcrec  # noqa: E402


def rotation(w):
    w = np.asarray(w, dtype=float)
    t = np.linalg.norm(w)
    if t < 1e-12:
        return np.eye(3)
    k = w / t
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--proto-dir", required=True)
    ap.add_argument("--recording", required=True)
    ap.add_argument("--truth", required=True)
    ap.add_argument("--max-translation-mm", type=float, default=float("inf"))
    ap.add_argument("--frame-map", help="headcast-sender --frames-csv: the input frame of each sequence number "
                    "(a live sender skips frames when it falls behind)")
    ap.add_argument("--from-sequence", type=int, default=0, help="compare the frames from this sequence number on")
    args = ap.parse_args()
    header, frames = hcrec.read_recording(args.recording, hcrec.load_proto(args.proto_dir))
    truth = json.load(open(args.truth))
    input_frame = {}
    if args.frame_map:
        with open(args.frame_map) as f:
            next(f)
            for line in f:
                sequence, index = line.strip().split(",")
                input_frame[int(sequence)] = int(index)
    frames = [f for f in frames if f.sequence >= args.from_sequence]
    t_err, z_err, r_err = [], [], []
    for f in frames:
        gt = truth["frames"][input_frame.get(f.sequence, f.sequence)]
        d = np.array(f.cam_translation) - np.array(gt["cam_translation"])
        t_err.append(1e3 * np.linalg.norm(d))
        z_err.append(1e3 * abs(d[2]))
        R = rotation(f.cam_rotation).T @ rotation(gt["cam_rotation"])
        r_err.append(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))
    shape = np.array(header.subject.shape) if header.subject.shape else np.zeros(len(truth["shape"]))
    out = {
        "frames": len(frames),
        "translation_error_mm_median": float(np.median(t_err)) if frames else None,
        "translation_error_mm_p95": float(np.percentile(t_err, 95)) if frames else None,
        "depth_error_mm_median": float(np.median(z_err)) if frames else None,
        "rotation_error_deg_median": float(np.median(r_err)) if frames else None,
        "shape_error_max": float(np.max(np.abs(shape - np.array(truth["shape"])))),
    }
    print(json.dumps(out, indent=2))
    if not frames or out["translation_error_mm_median"] > args.max_translation_mm:
        sys.exit(1)


if __name__ == "__main__":
    main()
