// HeadModel: a FLAME-layout parametric head (linear shape/expression bases, pose
// correctives, 5-joint linear blend skinning) and its single-frame Eigen forward pass.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>  // cross products on mesh rows
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "common/core/parallel_tasks.h"

namespace headcast {

// Joints in FLAME order. The root is the whole head+neck; "pose" in the
// parameter vector is 5 axis-angle triples in this order (15 numbers).
enum HeadJoint { kRootJoint = 0, kNeckJoint = 1, kJawJoint = 2, kLeftEyeJoint = 3, kRightEyeJoint = 4 };
constexpr int kNumHeadJoints = 5;
constexpr int kNumPoseParams = 3 * kNumHeadJoints;
constexpr int kNumPoseFeatures = 9 * (kNumHeadJoints - 1);  // (R - I) of the 4 non-root joints
constexpr int kNumLandmarks = 68;
constexpr int kNumContourLandmarks = 17;  // the jaw contour, landmarks 0..16
constexpr int kNumYawBins = 79;           // FLAME's dynamic contour table: yaw -39..39 degrees

using RowMatrixX3f = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
// 68 landmark positions in an image, pixels (dlib's order).
using Landmarks2d = std::array<Eigen::Vector2d, kNumLandmarks>;
using RowMatrixX3i = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowMatrixX2f = Eigen::Matrix<float, Eigen::Dynamic, 2, Eigen::RowMajor>;
using PoseVector = Eigen::Matrix<double, kNumPoseParams, 1>;

// Everything the on-disk format holds; see head_model_io.h for the key names.
struct HeadModelData {
  std::string name;                // e.g. "FLAME 2020", "ICT-FaceKit", "builtin"
  std::string description;         // free text: provenance, licence, caveats
  RowMatrixX3f v_template;         // N x 3, metres, y up, z out of the face
  Eigen::MatrixXf shapedirs;       // 3N x S (row 3i+c is vertex i coordinate c)
  Eigen::MatrixXf expressiondirs;  // 3N x E
  Eigen::MatrixXf posedirs;        // 3N x 36, offsets per (R - I) entry of joints 1..4
  Eigen::MatrixXf j_regressor;     // 5 x N
  Eigen::Matrix<float, Eigen::Dynamic, kNumHeadJoints, Eigen::RowMajor> weights;  // N x 5
  std::array<int, kNumHeadJoints> parents = {-1, 0, 1, 1, 1};
  RowMatrixX3i faces;  // F x 3, counter-clockwise seen from outside
  // 68 landmarks as barycentric points on faces (static embedding).
  Eigen::VectorXi lmk_faces;  // 68
  RowMatrixX3f lmk_bary;      // 68 x 3
  // Optional FLAME dynamic contour: for each of 79 yaw bins, 17 contour points.
  Eigen::MatrixXi dyn_lmk_faces;  // 79 x 17, or empty
  Eigen::MatrixXf dyn_lmk_bary;   // (79*17) x 3, row = bin*17 + k, or empty
  // Optional UV layout and albedo (linear texture model, values in [0, 1]).
  RowMatrixX2f uvs;       // T x 2, (u right, v down) in [0, 1], or empty
  RowMatrixX3i uv_faces;  // F x 3 indices into uvs, or empty
  int texture_height = 0, texture_width = 0;
  std::vector<float> texture_mean;            // H*W*3, RGB, row-major
  Eigen::MatrixXf texture_basis;              // (H*W*3) x T, or empty
  std::vector<std::string> shape_names;       // S names, or empty
  std::vector<std::string> expression_names;  // E names, or empty
  std::vector<std::string> texture_names;     // T names, or empty
  // The natural range of every expression coefficient, when the model has one:
  // ICT-FaceKit's ARKit-style blendshapes mean 0..1 (outside, the shapes are
  // not faces), PCA models (FLAME, built-in) have none (about +-2, METHOD §1).
  // A fitting prior, not geometry: it is not part of the fingerprint.
  float expression_min = -std::numeric_limits<float>::infinity();
  float expression_max = std::numeric_limits<float>::infinity();
  bool HasExpressionRange() const { return std::isfinite(expression_min) && std::isfinite(expression_max); }
};

struct HeadModelParams {
  Eigen::VectorXd shape;                 // beta, S values (fewer are zero-padded)
  Eigen::VectorXd expression;            // psi, E values (fewer are zero-padded)
  PoseVector pose = PoseVector::Zero();  // root, neck, jaw, left eye, right eye (axis-angle, rad)
};

// The per-identity part of the forward pass, computed once per beta.
struct HeadIdentity {
  Eigen::VectorXf shape;                                            // the beta it was made from
  Eigen::VectorXf v_shaped;                                         // 3N: template + shape offsets
  Eigen::Matrix<float, kNumHeadJoints, 3, Eigen::RowMajor> joints;  // rest joints for beta
};

struct HeadModelOutput {
  RowMatrixX3f vertices;  // N x 3, model frame (root joint's world)
  Eigen::Matrix<float, kNumLandmarks, 3, Eigen::RowMajor> landmarks;
  Eigen::Matrix<float, kNumHeadJoints, 3, Eigen::RowMajor> joints;  // posed joint positions
};

// Area-weighted unit vertex normals of any triangle mesh (zero for unused vertices).
RowMatrixX3f VertexNormals(const RowMatrixX3f& vertices, const RowMatrixX3i& faces);

class HeadModel {
 public:
  // Validates `data` (shapes, index ranges, finiteness) and throws
  // std::invalid_argument naming the field on any problem.
  explicit HeadModel(HeadModelData data);

  const HeadModelData& data() const { return data_; }
  int num_vertices() const { return static_cast<int>(data_.v_template.rows()); }
  int num_faces() const { return static_cast<int>(data_.faces.rows()); }
  int num_shape() const { return static_cast<int>(data_.shapedirs.cols()); }
  int num_expression() const { return static_cast<int>(data_.expressiondirs.cols()); }
  int num_texture() const { return static_cast<int>(data_.texture_basis.cols()); }
  bool has_texture() const { return !data_.texture_mean.empty() && data_.uvs.rows() > 0; }
  bool has_dynamic_contour() const { return data_.dyn_lmk_faces.size() > 0; }
  bool has_posedirs() const { return has_posedirs_; }
  // Joints that move any vertex. ICT-FaceKit has the root and the eyes; FLAME all five.
  bool JointIsArticulated(int joint) const { return articulated_[joint]; }
  // The pupil of an eye joint: the front-most (largest rest z) vertex mostly
  // skinned to it, the eyeball looking along +z at rest; -1 when the joint moves
  // nothing. What the tracker aims at the located iris.
  int PupilVertex(int eye_joint) const { return eye_joint == kLeftEyeJoint ? pupils_[0] : pupils_[1]; }
  // Index of a named expression component, or -1.
  int ExpressionIndex(const std::string& name) const;
  int ShapeIndex(const std::string& name) const;

  // A stable 16-hex-digit hash of topology, template and basis sizes; avatar
  // files record it so an avatar is never driven by another head model.
  const std::string& fingerprint() const { return fingerprint_; }

  HeadIdentity MakeIdentity(const Eigen::VectorXd& shape) const;
  // With `parallel`, the vertices are blended and skinned in two halves as two
  // tasks (the receiver's per-frame pass); the result is the same either way.
  void Forward(const HeadIdentity& identity, const Eigen::VectorXd& expression, const PoseVector& pose,
               HeadModelOutput* out, const ParallelTasks* parallel = nullptr) const;
  HeadModelOutput Forward(const HeadModelParams& params) const;

  // Landmark positions for already posed vertices and a given pose (the
  // contour choice depends on the head's yaw for FLAME).
  void ComputeLandmarks(const RowMatrixX3f& vertices, const PoseVector& pose,
                        Eigen::Matrix<float, kNumLandmarks, 3, Eigen::RowMajor>* landmarks) const;
  // Yaw bin (0..78) of FLAME's dynamic contour table for a pose.
  static int ContourYawBin(const PoseVector& pose);
  // Faces and barycentrics actually used for the 68 landmarks at this pose.
  void LandmarkEmbedding(const PoseVector& pose, Eigen::VectorXi* faces, RowMatrixX3f* bary) const;

  // A joint's rest position for the template and how it moves per shape and
  // expression unit (the joint regressor applied to the template and the bases).
  Eigen::Vector3f RestJoint(int joint) const { return j_template_.row(joint).transpose(); }
  Eigen::Matrix<float, 3, Eigen::Dynamic> JointShapeDirs(int joint) const {
    return j_shapedirs_.middleRows(3 * joint, 3);
  }
  Eigen::Matrix<float, 3, Eigen::Dynamic> JointExpressionDirs(int joint) const {
    return j_expressiondirs_.middleRows(3 * joint, 3);
  }

  // Mean of the 68 landmarks in the rest pose (head frame): where to aim a camera.
  const Eigen::Vector3d& rest_landmark_centroid() const { return rest_landmark_centroid_; }

  // Per-vertex normals (area weighted) of a posed mesh.
  RowMatrixX3f VertexNormals(const RowMatrixX3f& vertices) const;
  std::string Summary() const;

 private:
  void Validate() const;

  HeadModelData data_;
  // Joint regressor applied to the bases, so joints cost 15 x (S or E) per frame.
  Eigen::Matrix<float, kNumHeadJoints * 3, Eigen::Dynamic> j_shapedirs_, j_expressiondirs_;
  Eigen::Matrix<float, kNumHeadJoints, 3, Eigen::RowMajor> j_template_;
  // The expression basis row after row (3N x E): Forward's blend is then a dot
  // product per coordinate that streams the basis once, where the
  // column-major product walks the output E times.
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> expression_rows_;
  // Sparse skinning weights: for vertex i, entries [skin_begin_[i], skin_begin_[i+1]).
  std::vector<int> skin_begin_;
  std::vector<int> skin_joint_;
  std::vector<float> skin_weight_;
  bool has_posedirs_ = false;
  std::array<bool, kNumHeadJoints> articulated_{};
  std::array<int, 2> pupils_{-1, -1};  // left, right eye
  std::string fingerprint_;
  Eigen::Vector3d rest_landmark_centroid_;
};

}  // namespace headcast
