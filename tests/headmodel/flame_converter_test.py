#!/usr/bin/env python3
"""Tests deploy/tools/flame_to_npz.py on a small pickle built with FLAME's structure.

The pickle references chumpy.ch.Ch and scipy.sparse csc matrices exactly as the
official Python-2 FLAME pickles do (classes stood in here, so neither chumpy nor
scipy is needed), is converted, compared array by array, and then loaded by the
C++ loader through `headcast-headmodel summary`.
"""
import argparse
import os
import pickle
import subprocess
import sys
import tempfile
import types

import numpy as np

failures = []
checks = []


def check(cond, what):
    checks.append(what)
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


def make_fake_modules():
    chumpy = types.ModuleType("chumpy")
    chumpy_ch = types.ModuleType("chumpy.ch")

    class Ch:
        def __init__(self, x):
            self.x = x
            self._dirty_vars = set()

        def __getstate__(self):
            return {"x": self.x, "_dirty_vars": self._dirty_vars}

    Ch.__module__ = "chumpy.ch"
    Ch.__qualname__ = "Ch"
    chumpy_ch.Ch = Ch
    sparse = types.ModuleType("scipy.sparse._csc")

    class csc_matrix:
        def __init__(self, dense):
            dense = np.asarray(dense)
            self._shape = dense.shape
            data, indices, indptr = [], [], [0]
            for c in range(dense.shape[1]):
                for r in range(dense.shape[0]):
                    if dense[r, c] != 0:
                        data.append(dense[r, c])
                        indices.append(r)
                indptr.append(len(data))
            self.data, self.indices, self.indptr = np.array(data), np.array(indices), np.array(indptr)

        def __getstate__(self):
            return {"_shape": self._shape, "data": self.data, "indices": self.indices, "indptr": self.indptr, "maxprint": 50}

    csc_matrix.__module__ = "scipy.sparse._csc"
    csc_matrix.__qualname__ = "csc_matrix"
    sparse.csc_matrix = csc_matrix
    for name, mod in (("chumpy", chumpy), ("chumpy.ch", chumpy_ch), ("scipy.sparse._csc", sparse)):
        sys.modules[name] = mod
    return Ch, csc_matrix


def make_model(rng):
    # A small closed mesh: an octahedron subdivided once (18 vertices, 32 faces).
    n_side = 6
    ring = [(np.cos(a), np.sin(a)) for a in np.linspace(0, 2 * np.pi, n_side, endpoint=False)]
    verts = [(0, 1, 0)] + [(x, 0.5, z) for x, z in ring] + [(x, -0.5, z) for x, z in ring] + [(0, -1, 0)]
    v = np.array(verts, dtype=np.float64) * 0.1
    faces = []
    for j in range(n_side):
        k = (j + 1) % n_side
        faces += [(0, 1 + k, 1 + j), (1 + j, 1 + k, 1 + n_side + k), (1 + j, 1 + n_side + k, 1 + n_side + j),
                  (1 + n_side + j, 1 + n_side + k, 2 * n_side + 1)]
    f = np.array(faces, dtype=np.uint32)
    n = v.shape[0]
    weights = rng.random((n, 5))
    weights /= weights.sum(1, keepdims=True)
    j_reg = np.zeros((5, n))
    for j in range(5):
        ids = rng.choice(n, 3, replace=False)
        j_reg[j, ids] = 1 / 3
    return {
        "v_template": v,
        "shapedirs": rng.normal(0, 1e-3, (n, 3, 400 - 390)),  # 6 shape + 4 expression with --shape-total 6
        "posedirs": rng.normal(0, 1e-4, (n, 3, 36)),
        "J_regressor": j_reg,
        "weights": weights,
        "kintree_table": np.array([[4294967295, 0, 1, 1, 1], [0, 1, 2, 3, 4]], dtype=np.int64),
        "f": f,
        "bs_style": "lbs",
        "bs_type": "lrotmin",
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--script", required=True)
    ap.add_argument("--headmodel", required=True)
    args = ap.parse_args()
    Ch, csc_matrix = make_fake_modules()
    rng = np.random.default_rng(3)
    model = make_model(rng)
    stored = dict(model)
    stored["shapedirs"] = Ch(model["shapedirs"])
    stored["J_regressor"] = csc_matrix(model["J_regressor"])
    n_faces = model["f"].shape[0]
    emb = {
        "static_lmk_faces_idx": rng.integers(0, n_faces, 51),
        "static_lmk_bary_coords": np.full((51, 3), 1 / 3),
        "dynamic_lmk_faces_idx": rng.integers(0, n_faces, (79, 17)),
        "dynamic_lmk_bary_coords": np.tile(np.array([0.2, 0.3, 0.5]), (79, 17, 1)),
    }
    with tempfile.TemporaryDirectory() as tmp:
        pkl = os.path.join(tmp, "generic_model.pkl")
        with open(pkl, "wb") as fh:
            pickle.dump(stored, fh, protocol=2)
        npy = os.path.join(tmp, "landmark_embedding.npy")
        np.save(npy, emb, allow_pickle=True)
        out = os.path.join(tmp, "flame.npz")
        py = sys.executable
        # Run in a fresh interpreter that has no fake chumpy: the converter must not need it.
        r = subprocess.run([py, args.script, "--model", pkl, "--embedding", npy, "--shape", "6", "--shape-total", "6",
                            "--expression", "4", "--out", out], capture_output=True, text=True)
        print(r.stdout, r.stderr)
        check(r.returncode == 0, "converter succeeds on a chumpy/scipy pickle")
        d = np.load(out)
        check(np.allclose(d["v_template"], model["v_template"], atol=1e-7), "v_template round-trips")
        check(np.allclose(d["shapedirs"], model["shapedirs"][:, :, :6], atol=1e-7), "shape basis = first 6 components")
        check(np.allclose(d["expressiondirs"], model["shapedirs"][:, :, 6:10], atol=1e-7), "expression basis = next 4")
        check(np.allclose(d["posedirs"], model["posedirs"], atol=1e-7), "posedirs round-trip")
        check(np.allclose(d["J_regressor"], model["J_regressor"], atol=1e-7), "sparse J_regressor densified")
        check(np.allclose(d["weights"], model["weights"], atol=1e-7), "weights round-trip")
        check(np.array_equal(d["f"], model["f"].astype(np.int32)), "faces round-trip")
        check(d["kintree_table"][0, 0] == -1 and list(d["kintree_table"][0, 1:]) == [0, 1, 1, 1], "root parent -1")
        expected_lmk = np.concatenate([emb["dynamic_lmk_faces_idx"][0], emb["static_lmk_faces_idx"]])
        check(np.array_equal(d["lmk_faces_idx"], expected_lmk), "68 landmarks = frontal contour + 51 static")
        check(d["dynamic_lmk_faces_idx"].shape == (79, 17), "dynamic contour table kept")
        # The C++ loader accepts it.
        r = subprocess.run([args.headmodel, "summary", out], capture_output=True, text=True)
        print(r.stdout, r.stderr)
        check(r.returncode == 0 and "vertices:    14" in r.stdout and "dynamic contour" in r.stdout,
              "headcast-headmodel loads the converted model")
        # Bad input: a pickle without v_template names the key; a foreign file is refused.
        broken = dict(stored)
        del broken["v_template"]
        bad = os.path.join(tmp, "broken.pkl")
        with open(bad, "wb") as fh:
            pickle.dump(broken, fh, protocol=2)
        r = subprocess.run([py, args.script, "--model", bad, "--embedding", npy, "--out", out + "2"], capture_output=True, text=True)
        check(r.returncode == 2 and "v_template" in r.stderr and "Traceback" not in r.stderr, "missing key named, no traceback")
        foreign = os.path.join(tmp, "foreign.pkl")
        with open(foreign, "wb") as fh:
            fh.write(b"this is not a pickle at all")
        r = subprocess.run([py, args.script, "--model", foreign, "--embedding", npy, "--out", out + "3"], capture_output=True, text=True)
        check(r.returncode == 2 and "foreign.pkl" in r.stderr and "Traceback" not in r.stderr, "foreign file refused clearly")
    print(f"flame converter checks: {len(checks) - len(failures)} ok, {len(failures)} failing")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
