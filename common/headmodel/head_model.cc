// HeadModel: validation and the single-frame forward pass.
#include "common/headmodel/head_model.h"

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include "common/core/rotation.h"

namespace headcast {
namespace {

[[noreturn]] void Invalid(const std::string& field, const std::string& why) {
  throw std::invalid_argument("head model field '" + field + "': " + why);
}

template <typename M>
void CheckFinite(const std::string& field, const M& m) {
  if (!m.allFinite()) Invalid(field, "contains NaN or infinite values");
}

std::string Dims(Eigen::Index r, Eigen::Index c) { return std::to_string(r) + "x" + std::to_string(c); }

// FNV-1a, 64 bit: stable across platforms and builds, unlike std::hash.
uint64_t Fnv1a(uint64_t h, const void* data, size_t size) {
  const auto* p = static_cast<const uint8_t*>(data);
  for (size_t i = 0; i < size; ++i) {
    h ^= p[i];
    h *= 1099511628211ull;
  }
  return h;
}

Eigen::Matrix<float, 3, 4> RigidToMatrix(const Eigen::Matrix3f& R, const Eigen::Vector3f& t) {
  Eigen::Matrix<float, 3, 4> m;
  m.leftCols<3>() = R;
  m.col(3) = t;
  return m;
}

}  // namespace

HeadModel::HeadModel(HeadModelData data) : data_(std::move(data)) {
  Validate();
  const int n = num_vertices();
  // Joint regressor folded into the bases.
  j_template_.setZero();
  j_shapedirs_.setZero(kNumHeadJoints * 3, num_shape());
  j_expressiondirs_.setZero(kNumHeadJoints * 3, num_expression());
  for (int j = 0; j < kNumHeadJoints; ++j) {
    for (int i = 0; i < n; ++i) {
      const float w = data_.j_regressor(j, i);
      if (w == 0.f) continue;
      j_template_.row(j) += w * data_.v_template.row(i);
      for (int c = 0; c < 3; ++c) {
        j_shapedirs_.row(3 * j + c) += w * data_.shapedirs.row(3 * i + c);
        j_expressiondirs_.row(3 * j + c) += w * data_.expressiondirs.row(3 * i + c);
      }
    }
  }
  skin_begin_.assign(1, 0);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < kNumHeadJoints; ++j) {
      const float w = data_.weights(i, j);
      if (w != 0.f) {
        skin_joint_.push_back(j);
        skin_weight_.push_back(w);
        articulated_[j] = true;
      }
    }
    skin_begin_.push_back(static_cast<int>(skin_joint_.size()));
  }
  for (int e = 0; e < 2; ++e) {
    const int joint = e == 0 ? kLeftEyeJoint : kRightEyeJoint;
    for (int i = 0; i < n; ++i)
      if (data_.weights(i, joint) > 0.5f &&
          (pupils_[e] < 0 || data_.v_template(i, 2) > data_.v_template(pupils_[e], 2)))
        pupils_[e] = i;
  }
  has_posedirs_ = data_.posedirs.size() > 0 && data_.posedirs.cwiseAbs().maxCoeff() > 0.f;
  expression_rows_ = data_.expressiondirs;

  Eigen::Matrix<float, kNumLandmarks, 3, Eigen::RowMajor> rest;
  ComputeLandmarks(data_.v_template, PoseVector::Zero(), &rest);
  rest_landmark_centroid_ = rest.colwise().mean().cast<double>().transpose();

  uint64_t h = 1469598103934665603ull;
  const int64_t counts[] = {n, num_faces(), num_shape(), num_expression()};
  h = Fnv1a(h, counts, sizeof(counts));
  h = Fnv1a(h, data_.faces.data(), sizeof(int) * data_.faces.size());
  h = Fnv1a(h, data_.v_template.data(), sizeof(float) * data_.v_template.size());
  h = Fnv1a(h, data_.lmk_faces.data(), sizeof(int) * data_.lmk_faces.size());
  char hex[17];
  std::snprintf(hex, sizeof(hex), "%016llx", static_cast<unsigned long long>(h));
  fingerprint_ = hex;
}

void HeadModel::Validate() const {
  const auto& d = data_;
  const Eigen::Index n = d.v_template.rows();
  if (n < 3) Invalid("v_template", "needs at least 3 vertices, has " + std::to_string(n));
  CheckFinite("v_template", d.v_template);
  if (d.shapedirs.rows() != 3 * n)
    Invalid("shapedirs", "has " + Dims(d.shapedirs.rows() / 3, d.shapedirs.cols()) +
                             " vertices x components, expected " + std::to_string(n) + " vertices");
  if (d.expressiondirs.rows() != 3 * n)
    Invalid("expressiondirs",
            "expected " + std::to_string(n) + " vertices, got " + std::to_string(d.expressiondirs.rows() / 3));
  CheckFinite("shapedirs", d.shapedirs);
  CheckFinite("expressiondirs", d.expressiondirs);
  if (d.posedirs.size() > 0) {
    if (d.posedirs.rows() != 3 * n || d.posedirs.cols() != kNumPoseFeatures)
      Invalid("posedirs",
              "shape " + Dims(d.posedirs.rows(), d.posedirs.cols()) + ", expected " + Dims(3 * n, kNumPoseFeatures));
    CheckFinite("posedirs", d.posedirs);
  }
  if (d.j_regressor.rows() != kNumHeadJoints || d.j_regressor.cols() != n)
    Invalid("J_regressor",
            "shape " + Dims(d.j_regressor.rows(), d.j_regressor.cols()) + ", expected " + Dims(kNumHeadJoints, n));
  CheckFinite("J_regressor", d.j_regressor);
  if (d.weights.rows() != n)
    Invalid("weights", "has " + std::to_string(d.weights.rows()) + " rows, expected " + std::to_string(n));
  CheckFinite("weights", d.weights);
  for (Eigen::Index i = 0; i < n; ++i) {
    const float s = d.weights.row(i).sum();
    if (std::abs(s - 1.f) > 1e-3f)
      Invalid("weights", "row " + std::to_string(i) + " sums to " + std::to_string(s) + ", expected 1");
  }
  if (d.parents[0] != -1) Invalid("kintree_table", "joint 0 must be the root (parent -1)");
  for (int j = 1; j < kNumHeadJoints; ++j)
    if (d.parents[j] < 0 || d.parents[j] >= j)
      Invalid("kintree_table", "joint " + std::to_string(j) + " must have an earlier parent");
  if (d.faces.rows() < 1) Invalid("f", "no faces");
  if (d.faces.minCoeff() < 0 || d.faces.maxCoeff() >= n)
    Invalid("f", "vertex index out of range [0, " + std::to_string(n) + ")");
  if (d.lmk_faces.size() != kNumLandmarks || d.lmk_bary.rows() != kNumLandmarks)
    Invalid("lmk_faces_idx", "expected 68 landmark faces and 68x3 barycentrics, got " +
                                 std::to_string(d.lmk_faces.size()) + " and " + std::to_string(d.lmk_bary.rows()));
  if (d.lmk_faces.minCoeff() < 0 || d.lmk_faces.maxCoeff() >= d.faces.rows())
    Invalid("lmk_faces_idx", "face index out of range");
  CheckFinite("lmk_bary_coords", d.lmk_bary);
  if (d.dyn_lmk_faces.size() > 0) {
    if (d.dyn_lmk_faces.rows() != kNumYawBins || d.dyn_lmk_faces.cols() != kNumContourLandmarks ||
        d.dyn_lmk_bary.rows() != kNumYawBins * kNumContourLandmarks || d.dyn_lmk_bary.cols() != 3)
      Invalid("dynamic_lmk_faces_idx", "expected 79x17 faces and 79x17x3 barycentrics");
    if (d.dyn_lmk_faces.minCoeff() < 0 || d.dyn_lmk_faces.maxCoeff() >= d.faces.rows())
      Invalid("dynamic_lmk_faces_idx", "face index out of range");
    CheckFinite("dynamic_lmk_bary_coords", d.dyn_lmk_bary);
  }
  if (d.uvs.rows() > 0) {
    if (d.uv_faces.rows() != d.faces.rows()) Invalid("ft", "must have one row per face");
    if (d.uv_faces.minCoeff() < 0 || d.uv_faces.maxCoeff() >= d.uvs.rows()) Invalid("ft", "uv index out of range");
    CheckFinite("vt", d.uvs);
  }
  if (!d.texture_mean.empty()) {
    const size_t texels = static_cast<size_t>(d.texture_height) * d.texture_width * 3;
    if (d.texture_height <= 0 || d.texture_width <= 0 || d.texture_mean.size() != texels)
      Invalid("texture_mean", "size does not match its height x width x 3");
    if (d.texture_basis.size() > 0 && static_cast<size_t>(d.texture_basis.rows()) != texels)
      Invalid("texture_basis", "rows do not match texture_mean");
    for (float v : d.texture_mean)
      if (!std::isfinite(v)) Invalid("texture_mean", "contains NaN or infinite values");
    CheckFinite("texture_basis", d.texture_basis);
  }
  if (!d.shape_names.empty() && static_cast<Eigen::Index>(d.shape_names.size()) != d.shapedirs.cols())
    Invalid("shape_names", "count differs from shapedirs components");
  if (!d.expression_names.empty() && static_cast<Eigen::Index>(d.expression_names.size()) != d.expressiondirs.cols())
    Invalid("expression_names", "count differs from expressiondirs components");
  if (!(d.expression_min < d.expression_max))  // false for NaN too
    Invalid("expression_range", "needs min < max");
}

int HeadModel::ExpressionIndex(const std::string& name) const {
  for (size_t i = 0; i < data_.expression_names.size(); ++i)
    if (data_.expression_names[i] == name) return static_cast<int>(i);
  return -1;
}
int HeadModel::ShapeIndex(const std::string& name) const {
  for (size_t i = 0; i < data_.shape_names.size(); ++i)
    if (data_.shape_names[i] == name) return static_cast<int>(i);
  return -1;
}

HeadIdentity HeadModel::MakeIdentity(const Eigen::VectorXd& shape) const {
  HeadIdentity id;
  const int s = std::min<int>(static_cast<int>(shape.size()), num_shape());
  id.shape = Eigen::VectorXf::Zero(num_shape());
  id.shape.head(s) = shape.head(s).cast<float>();
  id.v_shaped = Eigen::Map<const Eigen::VectorXf>(data_.v_template.data(), 3 * num_vertices());
  if (s > 0) id.v_shaped.noalias() += data_.shapedirs.leftCols(s) * id.shape.head(s);
  Eigen::Matrix<float, kNumHeadJoints * 3, 1> j = Eigen::Map<const Eigen::Matrix<float, 15, 1>>(j_template_.data());
  if (s > 0) j.noalias() += j_shapedirs_.leftCols(s) * id.shape.head(s);
  id.joints = Eigen::Map<const Eigen::Matrix<float, kNumHeadJoints, 3, Eigen::RowMajor>>(j.data());
  return id;
}

void HeadModel::Forward(const HeadIdentity& identity, const Eigen::VectorXd& expression, const PoseVector& pose,
                        HeadModelOutput* out, const ParallelTasks* parallel) const {
  const int n = num_vertices();
  const int e = std::min<int>(static_cast<int>(expression.size()), num_expression());
  const Eigen::VectorXf psi = expression.head(e).cast<float>();
  Eigen::Matrix<float, kNumHeadJoints * 3, 1> jflat =
      Eigen::Map<const Eigen::Matrix<float, 15, 1>>(identity.joints.data());
  if (e > 0) jflat.noalias() += j_expressiondirs_.leftCols(e) * psi;
  const Eigen::Map<const Eigen::Matrix<float, kNumHeadJoints, 3, Eigen::RowMajor>> J(jflat.data());

  std::array<Eigen::Matrix3f, kNumHeadJoints> R;
  for (int k = 0; k < kNumHeadJoints; ++k) R[k] = AxisAngleToMatrix(pose.segment<3>(3 * k)).cast<float>();
  Eigen::Matrix<float, kNumPoseFeatures, 1> feature;
  for (int k = 1; k < kNumHeadJoints; ++k) {
    const Eigen::Matrix3f d = R[k] - Eigen::Matrix3f::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) feature[9 * (k - 1) + 3 * r + c] = d(r, c);
  }

  // Kinematic chain: world_from_joint G_k, then skinning transforms A_k = G_k * T(-J_k).
  std::array<Eigen::Matrix3f, kNumHeadJoints> GR;
  std::array<Eigen::Vector3f, kNumHeadJoints> Gt;
  std::array<Eigen::Matrix<float, 3, 4>, kNumHeadJoints> A;
  for (int k = 0; k < kNumHeadJoints; ++k) {
    const int p = data_.parents[k];
    const Eigen::Vector3f jk = J.row(k).transpose();
    if (p < 0) {
      GR[k] = R[k];
      Gt[k] = jk;
    } else {
      GR[k] = GR[p] * R[k];
      Gt[k] = GR[p] * (jk - J.row(p).transpose()) + Gt[p];
    }
    A[k] = RigidToMatrix(GR[k], Gt[k] - GR[k] * jk);
    out->joints.row(k) = Gt[k].transpose();
  }

  // Blend and skin vertices [begin, end): the blend, a product with the whole
  // expression basis, is the bulk of the pass, and vertices are independent.
  out->vertices.resize(n, 3);
  auto blend_and_skin = [&](int begin, int end) {
    const int rows = 3 * (end - begin);
    Eigen::Map<Eigen::VectorXf> v(out->vertices.data() + 3 * begin, rows);
    v = identity.v_shaped.segment(3 * begin, rows);
    if (e > 0) v.noalias() += expression_rows_.block(3 * begin, 0, rows, e) * psi;
    if (has_posedirs_) v.noalias() += data_.posedirs.middleRows(3 * begin, rows) * feature;
    for (int i = begin; i < end; ++i) {
      Eigen::Matrix<float, 3, 4> T = Eigen::Matrix<float, 3, 4>::Zero();
      for (int s = skin_begin_[i]; s < skin_begin_[i + 1]; ++s) T += skin_weight_[s] * A[skin_joint_[s]];
      const Eigen::Vector3f p = out->vertices.row(i).transpose();
      out->vertices.row(i) = (T.leftCols<3>() * p + T.col(3)).transpose();
    }
  };
  if (parallel && *parallel)
    (*parallel)(2, [&](int k) { k == 0 ? blend_and_skin(0, n / 2) : blend_and_skin(n / 2, n); });
  else
    blend_and_skin(0, n);
  ComputeLandmarks(out->vertices, pose, &out->landmarks);
}

HeadModelOutput HeadModel::Forward(const HeadModelParams& params) const {
  HeadModelOutput out;
  Forward(MakeIdentity(params.shape), params.expression, params.pose, &out);
  return out;
}

int HeadModel::ContourYawBin(const PoseVector& pose) {
  // FLAME's table is indexed by the yaw of root*neck in whole degrees: 0..39
  // for turns one way, 40..78 for -1..-39 the other way, clamped at 39.
  const Eigen::Matrix3d R = AxisAngleToMatrix(pose.segment<3>(0)) * AxisAngleToMatrix(pose.segment<3>(3));
  const double yaw_deg = std::round(std::min(-YawOfMatrix(R) * 180.0 / M_PI, 39.0));
  if (yaw_deg >= 0) return static_cast<int>(yaw_deg);
  if (yaw_deg < -39) return 78;
  return static_cast<int>(39 - yaw_deg);
}

void HeadModel::LandmarkEmbedding(const PoseVector& pose, Eigen::VectorXi* faces, RowMatrixX3f* bary) const {
  *faces = data_.lmk_faces;
  *bary = data_.lmk_bary;
  if (!has_dynamic_contour()) return;
  const int bin = ContourYawBin(pose);
  for (int k = 0; k < kNumContourLandmarks; ++k) {
    (*faces)[k] = data_.dyn_lmk_faces(bin, k);
    bary->row(k) = data_.dyn_lmk_bary.row(bin * kNumContourLandmarks + k);
  }
}

void HeadModel::ComputeLandmarks(const RowMatrixX3f& vertices, const PoseVector& pose,
                                 Eigen::Matrix<float, kNumLandmarks, 3, Eigen::RowMajor>* landmarks) const {
  const bool dynamic = has_dynamic_contour();
  const int bin = dynamic ? ContourYawBin(pose) : 0;
  for (int l = 0; l < kNumLandmarks; ++l) {
    int f = data_.lmk_faces[l];
    Eigen::RowVector3f b = data_.lmk_bary.row(l);
    if (dynamic && l < kNumContourLandmarks) {
      f = data_.dyn_lmk_faces(bin, l);
      b = data_.dyn_lmk_bary.row(bin * kNumContourLandmarks + l);
    }
    landmarks->row(l) = b[0] * vertices.row(data_.faces(f, 0)) + b[1] * vertices.row(data_.faces(f, 1)) +
                        b[2] * vertices.row(data_.faces(f, 2));
  }
}

RowMatrixX3f VertexNormals(const RowMatrixX3f& v, const RowMatrixX3i& faces) {
  RowMatrixX3f normals = RowMatrixX3f::Zero(v.rows(), 3);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const int a = faces(f, 0), b = faces(f, 1), c = faces(f, 2);
    const Eigen::RowVector3f n = (v.row(b) - v.row(a)).cross(v.row(c) - v.row(a));  // area weighted
    normals.row(a) += n;
    normals.row(b) += n;
    normals.row(c) += n;
  }
  for (int i = 0; i < normals.rows(); ++i) {
    const float len = normals.row(i).norm();
    if (len > 0) normals.row(i) /= len;
  }
  return normals;
}

RowMatrixX3f HeadModel::VertexNormals(const RowMatrixX3f& vertices) const {
  return headcast::VertexNormals(vertices, data_.faces);
}

std::string HeadModel::Summary() const {
  std::ostringstream s;
  const Eigen::RowVector3f lo = data_.v_template.colwise().minCoeff(), hi = data_.v_template.colwise().maxCoeff();
  s << "name:        " << data_.name << "\n"
    << "fingerprint: " << fingerprint_ << "\n"
    << "vertices:    " << num_vertices() << "\n"
    << "faces:       " << num_faces() << "\n"
    << "shape:       " << num_shape() << " components\n"
    << "expression:  " << num_expression() << " components\n"
    << "posedirs:    " << (has_posedirs_ ? "yes" : "none (no pose correctives)") << "\n"
    << "joints:      ";
  const char* names[] = {"root", "neck", "jaw", "left_eye", "right_eye"};
  for (int k = 0; k < kNumHeadJoints; ++k) s << names[k] << (articulated_[k] ? "" : "(static)") << " ";
  s << "\nlandmarks:   68" << (has_dynamic_contour() ? " (dynamic contour by yaw)" : " (fixed)") << "\n"
    << "texture:     "
    << (has_texture() ? std::to_string(data_.texture_width) + "x" + std::to_string(data_.texture_height) + ", " +
                            std::to_string(num_texture()) + " components"
                      : "none")
    << "\n"
    << "extent (m):  x " << lo[0] << ".." << hi[0] << "  y " << lo[1] << ".." << hi[1] << "  z " << lo[2] << ".."
    << hi[2] << "\n";
  if (!data_.expression_names.empty()) {
    s << "expressions:";
    for (const auto& n : data_.expression_names) s << " " << n;
    s << "\n";
  }
  if (!data_.shape_names.empty()) {
    s << "shapes:     ";
    for (const auto& n : data_.shape_names) s << " " << n;
    s << "\n";
  }
  if (!data_.description.empty()) s << "about:       " << data_.description << "\n";
  return s.str();
}

}  // namespace headcast
