// The one on-disk head-model format (.npz with FLAME key names) and its loader.
//
// Keys (N vertices, F faces, S shape, E expression, T texture components):
//   headcast_format   int32 (1,)        format version, currently 1
//   v_template        float (N,3)       metres, y up, z out of the face
//   shapedirs         float (N,3,S)     identity basis
//   expressiondirs    float (N,3,E)     expression basis
//     either basis may instead be int16 (N,3,K) with KEY_step float (1,): metres a step
//     (the compact form shipped models use; written with HeadModelSaveOptions::basis_step)
//   posedirs          float (N,3,36)    pose correctives (optional; FLAME layout)
//   J_regressor       float (5,N)       root, neck, jaw, left eye, right eye
//   weights           float (N,5)       skinning weights, rows sum to 1
//   kintree_table     int   (2,5)       row 0: parents (root's is -1 or any value)
//   f                 int   (F,3)       triangles
//   lmk_faces_idx     int   (68,)       landmark faces, iBUG/dlib order
//   lmk_bary_coords   float (68,3)      landmark barycentrics
//   dynamic_lmk_faces_idx   int (79,17)    optional FLAME contour table by yaw
//   dynamic_lmk_bary_coords float (79,17,3)
//   vt float (V,2), ft int (F,3)        optional UVs (v down, [0,1])
//   texture_mean float (H,W,3), texture_basis float (H,W,3,T)  optional albedo, RGB in [0,1]
//   expression_range float (2,)        optional natural [min, max] of every expression coefficient
//   name, description, shape_names, expression_names, texture_names:
//                     uint8 UTF-8 text, names one per line (optional)
#pragma once

#include <string>

#include "common/headmodel/head_model.h"

namespace headcast {

constexpr int kHeadModelFormatVersion = 1;

// Throws std::runtime_error naming the file and the key on any problem
// (missing key, wrong shape or dtype, NaN, bad indices, unreadable file).
HeadModel LoadHeadModel(const std::string& path);
struct HeadModelSaveOptions {
  // 0: the bases as float32. > 0: as int16 multiples of this many metres
  // (a few MB instead of tens for ICT-FaceKit; throws when a value does not fit).
  double basis_step = 0;
};
void SaveHeadModel(const HeadModel& model, const std::string& path, const HeadModelSaveOptions& options = {});

// "builtin" for the procedural head, otherwise a path to a model .npz.
HeadModel LoadHeadModelSpec(const std::string& spec);

}  // namespace headcast
