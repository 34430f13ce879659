#!/usr/bin/env python3
"""Convert an official FLAME model (2020, 2023, 2023 Open) into headcast's head-model .npz.

FLAME cannot be redistributed: download it yourself (flame.is.tue.mpg.de), then

    python3 deploy/tools/flame_to_npz.py --model generic_model.pkl \
        --embedding landmark_embedding.npy [--texture FLAME_texture.npz] --out flame.npz

Needs only Debian's python3-numpy. The FLAME pickles were written by Python 2
with chumpy arrays and scipy sparse matrices inside; both are unpickled here by
small stand-ins, so neither chumpy nor scipy is required.

Landmark embeddings accepted:
  * a .npy dict with static_lmk_faces_idx / static_lmk_bary_coords (51 points),
    dynamic_lmk_faces_idx / dynamic_lmk_bary_coords (79 yaw bins x 17 contour
    points) and optionally full_lmk_faces_idx / full_lmk_bary_coords (68);
  * FLAME's flame_static_embedding.pkl (lmk_face_idx, lmk_b_coords; 51 points)
    together with --dynamic-embedding flame_dynamic_embedding.npy.
The output keys are documented in common/headmodel/head_model_io.h.
"""
import argparse
import pickle
import sys

import numpy as np

FORMAT_VERSION = 1
NUM_JOINTS = 5
NUM_POSE_FEATURES = 36


class ConversionError(Exception):
    pass


class _ChumpyStandIn:
    """Receives the state of a pickled chumpy object; its array is under 'x'."""

    def __init__(self, *args, **kwargs):
        pass

    def __setstate__(self, state):
        self.__dict__.update(state if isinstance(state, dict) else {"x": state})


class _SparseStandIn:
    """Receives the state of a pickled scipy.sparse matrix (csc/csr/coo)."""

    kind = "csc"

    def __init__(self, *args, **kwargs):
        pass

    def __setstate__(self, state):
        self.__dict__.update(state)

    def dense(self):
        shape = tuple(self.__dict__.get("_shape") or self.__dict__.get("shape"))
        out = np.zeros(shape, dtype=np.float64)
        if self.kind == "coo":
            np.add.at(out, (np.asarray(self.row), np.asarray(self.col)), np.asarray(self.data))
            return out
        data, indices, indptr = np.asarray(self.data), np.asarray(self.indices), np.asarray(self.indptr)
        for major in range(len(indptr) - 1):
            for k in range(indptr[major], indptr[major + 1]):
                if self.kind == "csc":
                    out[indices[k], major] += data[k]
                else:
                    out[major, indices[k]] += data[k]
        return out


def _sparse_class(kind):
    return type("_Sparse_" + kind, (_SparseStandIn,), {"kind": kind})


class _Unpickler(pickle.Unpickler):
    def find_class(self, module, name):
        if module.startswith("chumpy"):
            return _ChumpyStandIn
        if module.startswith("scipy.sparse"):
            for kind in ("csc", "csr", "coo"):
                if name.startswith(kind):
                    return _sparse_class(kind)
            raise ConversionError(f"unsupported sparse matrix type {module}.{name}")
        return super().find_class(module, name)


def load_pickle(path):
    try:
        with open(path, "rb") as f:
            return _Unpickler(f, encoding="latin1").load()
    except FileNotFoundError:
        raise ConversionError(f"{path}: no such file")
    except (pickle.UnpicklingError, EOFError, ValueError, AttributeError, ImportError) as e:
        raise ConversionError(f"{path}: not a readable FLAME pickle ({e})")


def as_array(value, where):
    if isinstance(value, _ChumpyStandIn):
        if "x" not in value.__dict__:
            raise ConversionError(f"{where}: chumpy object without an array (keys: {sorted(value.__dict__)})")
        value = value.x
    if isinstance(value, _SparseStandIn):
        return value.dense()
    if hasattr(value, "toarray"):  # a real scipy matrix, if scipy was importable
        return value.toarray()
    return np.asarray(value)


def get(model, key, where):
    if key not in model:
        raise ConversionError(f"{where}: key '{key}' missing (keys present: {sorted(model)})")
    return as_array(model[key], f"{where}:{key}")


def check_finite(name, array):
    if not np.all(np.isfinite(array)):
        raise ConversionError(f"{name} contains NaN or infinite values")


def load_embedding(path, dynamic_path):
    if path.endswith(".npy"):
        try:
            emb = np.load(path, allow_pickle=True, encoding="latin1")[()]
        except Exception as e:  # numpy raises several types for foreign files
            raise ConversionError(f"{path}: not a readable landmark embedding ({e})")
    else:
        emb = load_pickle(path)
    if not isinstance(emb, dict):
        raise ConversionError(f"{path}: expected a dict of arrays")
    keys = set(emb)
    if {"static_lmk_faces_idx", "static_lmk_bary_coords"} <= keys:
        static_f = np.asarray(emb["static_lmk_faces_idx"]).reshape(-1)
        static_b = np.asarray(emb["static_lmk_bary_coords"]).reshape(-1, 3)
        dyn_f = np.asarray(emb.get("dynamic_lmk_faces_idx")) if "dynamic_lmk_faces_idx" in keys else None
        dyn_b = np.asarray(emb.get("dynamic_lmk_bary_coords")) if "dynamic_lmk_bary_coords" in keys else None
        full_f = np.asarray(emb["full_lmk_faces_idx"]).reshape(-1) if "full_lmk_faces_idx" in keys else None
        full_b = np.asarray(emb["full_lmk_bary_coords"]).reshape(-1, 3) if "full_lmk_bary_coords" in keys else None
    elif {"lmk_face_idx", "lmk_b_coords"} <= keys:
        static_f = np.asarray(emb["lmk_face_idx"]).reshape(-1)
        static_b = np.asarray(emb["lmk_b_coords"]).reshape(-1, 3)
        dyn_f = dyn_b = full_f = full_b = None
    else:
        raise ConversionError(f"{path}: unknown landmark embedding (keys: {sorted(keys)})")
    if dynamic_path:
        dyn = np.load(dynamic_path, allow_pickle=True, encoding="latin1")[()]
        dyn_f = np.asarray(dyn["lmk_face_idx"])
        dyn_b = np.asarray(dyn["lmk_b_coords"])
    if static_f.shape[0] != 51 or static_b.shape != (51, 3):
        raise ConversionError(f"{path}: expected 51 static landmarks, got {static_f.shape[0]}")
    if dyn_f is not None:
        dyn_f = dyn_f.reshape(79, 17)
        dyn_b = dyn_b.reshape(79, 17, 3)
    if full_f is not None and full_f.shape[0] == 68:
        lmk_f, lmk_b = full_f, full_b
    elif dyn_f is not None:
        # 68 = the 17 contour points of the frontal yaw bin, then the 51 static ones.
        lmk_f = np.concatenate([dyn_f[0], static_f])
        lmk_b = np.concatenate([dyn_b[0], static_b])
    else:
        raise ConversionError(f"{path}: has only the 51 inner landmarks; give the contour with --dynamic-embedding")
    return lmk_f, lmk_b, dyn_f, dyn_b


def text(s):
    return np.frombuffer(s.encode("utf-8"), dtype=np.uint8)


def convert(args):
    model = load_pickle(args.model)
    if not isinstance(model, dict):
        raise ConversionError(f"{args.model}: expected a dict, got {type(model).__name__}")
    where = args.model
    v_template = get(model, "v_template", where).astype(np.float32)
    n = v_template.shape[0]
    if v_template.shape != (n, 3):
        raise ConversionError(f"{where}:v_template: shape {v_template.shape}, expected (N, 3)")
    dirs = get(model, "shapedirs", where).astype(np.float32)
    if dirs.ndim != 3 or dirs.shape[:2] != (n, 3):
        raise ConversionError(f"{where}:shapedirs: shape {dirs.shape}, expected ({n}, 3, K)")
    split = args.shape_total if dirs.shape[2] > args.shape_total else dirs.shape[2]
    shapedirs = dirs[:, :, : min(args.shape, split)]
    expressiondirs = dirs[:, :, split : split + args.expression]
    if expressiondirs.shape[2] == 0:
        raise ConversionError(f"{where}:shapedirs: {dirs.shape[2]} components, none left for expressions after {split} shape components")
    posedirs = get(model, "posedirs", where).astype(np.float32)
    if posedirs.shape != (n, 3, NUM_POSE_FEATURES):
        raise ConversionError(f"{where}:posedirs: shape {posedirs.shape}, expected ({n}, 3, 36)")
    j_regressor = get(model, "J_regressor", where).astype(np.float32)
    if j_regressor.shape != (NUM_JOINTS, n):
        raise ConversionError(f"{where}:J_regressor: shape {j_regressor.shape}, expected (5, {n})")
    weights = get(model, "weights", where).astype(np.float32)
    if weights.shape != (n, NUM_JOINTS):
        raise ConversionError(f"{where}:weights: shape {weights.shape}, expected ({n}, 5)")
    kintree = get(model, "kintree_table", where).astype(np.int64)
    if kintree.shape != (2, NUM_JOINTS):
        raise ConversionError(f"{where}:kintree_table: shape {kintree.shape}, expected (2, 5)")
    kintree = kintree.copy()
    kintree[0, 0] = -1  # FLAME stores the root's parent as 2^32 - 1
    faces = get(model, "f", where).astype(np.int32)
    for name, array in (("v_template", v_template), ("shapedirs", dirs), ("posedirs", posedirs),
                        ("J_regressor", j_regressor), ("weights", weights)):
        check_finite(f"{where}:{name}", array)

    lmk_f, lmk_b, dyn_f, dyn_b = load_embedding(args.embedding, args.dynamic_embedding)
    out = {
        "headcast_format": np.array([FORMAT_VERSION], dtype=np.int32),
        "v_template": v_template,
        "shapedirs": np.ascontiguousarray(shapedirs),
        "expressiondirs": np.ascontiguousarray(expressiondirs),
        "posedirs": posedirs,
        "J_regressor": j_regressor,
        "weights": weights,
        "kintree_table": kintree.astype(np.int32),
        "f": faces,
        "lmk_faces_idx": lmk_f.astype(np.int32),
        "lmk_bary_coords": lmk_b.astype(np.float32),
        "name": text(args.name),
        "description": text("FLAME, converted by headcast's flame_to_npz.py from the user's own download; "
                            "subject to the FLAME licence."),
    }
    if dyn_f is not None:
        out["dynamic_lmk_faces_idx"] = dyn_f.astype(np.int32)
        out["dynamic_lmk_bary_coords"] = dyn_b.astype(np.float32)
    if args.texture:
        try:
            tex = np.load(args.texture)
        except Exception as e:
            raise ConversionError(f"{args.texture}: not a readable texture npz ({e})")
        for key in ("mean", "tex_dir", "vt", "ft"):
            if key not in tex:
                raise ConversionError(f"{args.texture}: key '{key}' missing")
        mean = tex["mean"].astype(np.float32)
        h, w = mean.shape[:2]
        basis = tex["tex_dir"].astype(np.float32).reshape(h, w, 3, -1)[:, :, :, : args.texture_components]
        if mean.max() > 2:  # stored in 0..255
            mean, basis = mean / 255.0, basis / 255.0
        if args.texture_bgr:
            mean, basis = mean[:, :, ::-1], basis[:, :, ::-1, :]
        vt = tex["vt"].astype(np.float32).copy()
        vt[:, 1] = 1.0 - vt[:, 1]  # OBJ-style v up -> headcast's v down
        out["texture_mean"] = np.ascontiguousarray(mean)
        out["texture_basis"] = np.ascontiguousarray(basis)
        out["vt"] = vt
        out["ft"] = tex["ft"].astype(np.int32)
    np.savez_compressed(args.out, **out)
    print(f"wrote {args.out}: {n} vertices, {faces.shape[0]} faces, {shapedirs.shape[2]} shape, "
          f"{expressiondirs.shape[2]} expression components"
          + (", dynamic contour" if dyn_f is not None else ""))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", required=True, help="FLAME generic_model.pkl")
    p.add_argument("--embedding", required=True, help="landmark embedding (.npy dict or static .pkl)")
    p.add_argument("--dynamic-embedding", help="flame_dynamic_embedding.npy, when --embedding is the static pkl")
    p.add_argument("--texture", help="FLAME_texture.npz (optional albedo PCA and UVs)")
    p.add_argument("--texture-components", type=int, default=50)
    p.add_argument("--texture-bgr", type=int, default=1, help="1 if the texture npz stores BGR (as FLAME_texture.npz does)")
    p.add_argument("--shape", type=int, default=300, help="shape components to keep")
    p.add_argument("--expression", type=int, default=100, help="expression components to keep")
    p.add_argument("--shape-total", type=int, default=300, help="shape components before the expression ones in shapedirs")
    p.add_argument("--name", default="FLAME")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    try:
        convert(args)
    except ConversionError as e:
        print(f"flame_to_npz: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
