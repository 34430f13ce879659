// Reading and writing head models as .npz.
#include "common/headmodel/head_model_io.h"

#include <cmath>
#include <stdexcept>

#include "common/core/npy.h"
#include "common/headmodel/builtin_head.h"

namespace headcast {
namespace {

class Reader {
 public:
  Reader(std::string path, NpzArchive archive) : path_(std::move(path)), archive_(std::move(archive)) {}

  [[noreturn]] void Fail(const std::string& key, const std::string& why) const {
    throw std::runtime_error(path_ + ": key '" + key + "': " + why);
  }
  bool Has(const std::string& key) const { return archive_.count(key) > 0; }

  // The array under `key` with `dims` (-1 = any), checked for dtype and finiteness.
  const NpyArray& Get(const std::string& key, const std::vector<int64_t>& dims, bool integer) const {
    auto it = archive_.find(key);
    if (it == archive_.end())
      Fail(key, "missing (is this a headcast head model? convert sources with headcast-headmodel convert)");
    const NpyArray& a = it->second;
    bool shape_ok = a.ndim() == static_cast<int>(dims.size());
    for (size_t i = 0; shape_ok && i < dims.size(); ++i) shape_ok = dims[i] < 0 || a.dim(i) == dims[i];
    if (!shape_ok) {
      std::string want = "(";
      for (size_t i = 0; i < dims.size(); ++i)
        want += (i ? ", " : "") + (dims[i] < 0 ? std::string("*") : std::to_string(dims[i]));
      Fail(key, "shape " + a.ShapeString() + ", expected " + want + ")");
    }
    const bool is_int = a.dtype() == DType::kInt32 || a.dtype() == DType::kInt64;
    const bool is_float = a.dtype() == DType::kFloat32 || a.dtype() == DType::kFloat64;
    if (integer && !is_int) Fail(key, std::string("dtype ") + DTypeName(a.dtype()) + ", expected int32 or int64");
    if (!integer && !is_float)
      Fail(key, std::string("dtype ") + DTypeName(a.dtype()) + ", expected float32 or float64");
    if (!integer)
      for (float v : a.ToFloats())
        if (!std::isfinite(v)) Fail(key, "contains NaN or infinite values");
    return a;
  }
  std::vector<float> Floats(const std::string& key, const std::vector<int64_t>& dims) const {
    return Get(key, dims, false).ToFloats();
  }
  // A basis stored as floats, or compactly as int16 steps with `KEY_step`
  // (metres a step) beside it (SaveOptions::basis_step).
  const NpyArray& Basis(const std::string& key, const std::vector<int64_t>& dims, std::vector<float>* values) const {
    auto it = archive_.find(key);
    if (it == archive_.end() || it->second.dtype() != DType::kInt16) {
      const NpyArray& a = Get(key, dims, false);
      *values = a.ToFloats();
      return a;
    }
    const std::vector<float> step = Floats(key + "_step", {1});
    if (!(step[0] > 0) || !std::isfinite(step[0])) Fail(key + "_step", "must be a positive step");
    const NpyArray& a = it->second;
    bool shape_ok = a.ndim() == static_cast<int>(dims.size());
    for (size_t i = 0; shape_ok && i < dims.size(); ++i) shape_ok = dims[i] < 0 || a.dim(i) == dims[i];
    if (!shape_ok) Fail(key, "shape " + a.ShapeString() + " does not fit the model");
    *values = a.ToFloats();
    for (float& v : *values) v *= step[0];
    return a;
  }
  std::vector<int64_t> Ints(const std::string& key, const std::vector<int64_t>& dims) const {
    return Get(key, dims, true).ToInt64s();
  }
  std::vector<std::string> Strings(const std::string& key) const {
    auto it = archive_.find(key);
    if (it == archive_.end()) return {};
    if (it->second.dtype() != DType::kUInt8 || it->second.ndim() != 1)
      Fail(key, "expected uint8 text (one name per line)");
    return NpyToStrings(it->second);
  }
  const NpyArray& Raw(const std::string& key) const { return archive_.at(key); }

 private:
  std::string path_;
  NpzArchive archive_;
};

// (N,3,K) numpy layout -> 3N x K column-major basis.
Eigen::MatrixXf BasisFromNK3(const std::vector<float>& v, int64_t n, int64_t k) {
  Eigen::MatrixXf m(3 * n, k);
  for (int64_t r = 0; r < 3 * n; ++r)
    for (int64_t c = 0; c < k; ++c) m(r, c) = v[r * k + c];
  return m;
}
std::vector<float> BasisToNK3(const Eigen::MatrixXf& m) {
  std::vector<float> v(m.size());
  for (int64_t r = 0; r < m.rows(); ++r)
    for (int64_t c = 0; c < m.cols(); ++c) v[r * m.cols() + c] = m(r, c);
  return v;
}

// numpy row-major data <-> Eigen matrices of any storage order and scalar.
template <typename Matrix, typename T>
Matrix RowMajorFrom(const std::vector<T>& v, int64_t rows, int64_t cols) {
  Matrix m(rows, cols);
  for (int64_t r = 0; r < rows; ++r)
    for (int64_t c = 0; c < cols; ++c) m(r, c) = static_cast<typename Matrix::Scalar>(v[r * cols + c]);
  return m;
}
template <typename T, typename Matrix>
std::vector<T> RowMajorValues(const Matrix& m) {
  std::vector<T> v(m.size());
  for (int64_t r = 0; r < m.rows(); ++r)
    for (int64_t c = 0; c < m.cols(); ++c) v[r * m.cols() + c] = static_cast<T>(m(r, c));
  return v;
}

}  // namespace

HeadModel LoadHeadModel(const std::string& path) {
  Reader in(path, ReadNpz(path));
  if (in.Has("headcast_format")) {
    const auto version = in.Ints("headcast_format", {1});
    if (version[0] != kHeadModelFormatVersion)
      in.Fail("headcast_format", "format version " + std::to_string(version[0]) +
                                     " is not supported (this build reads version " +
                                     std::to_string(kHeadModelFormatVersion) + ")");
  }
  HeadModelData d;
  const auto& vt = in.Get("v_template", {-1, 3}, false);
  const int64_t n = vt.dim(0);
  d.v_template = RowMajorFrom<RowMatrixX3f>(vt.ToFloats(), n, 3);
  std::vector<float> values;
  const auto& sd = in.Basis("shapedirs", {n, 3, -1}, &values);
  d.shapedirs = BasisFromNK3(values, n, sd.dim(2));
  const auto& ed = in.Basis("expressiondirs", {n, 3, -1}, &values);
  d.expressiondirs = BasisFromNK3(values, n, ed.dim(2));
  if (in.Has("posedirs"))
    d.posedirs = BasisFromNK3(in.Floats("posedirs", {n, 3, kNumPoseFeatures}), n, kNumPoseFeatures);
  d.j_regressor = RowMajorFrom<Eigen::MatrixXf>(in.Floats("J_regressor", {kNumHeadJoints, n}), kNumHeadJoints, n);
  d.weights = RowMajorFrom<decltype(d.weights)>(in.Floats("weights", {n, kNumHeadJoints}), n, kNumHeadJoints);
  const auto kintree = in.Ints("kintree_table", {2, kNumHeadJoints});
  d.parents[0] = -1;
  for (int j = 1; j < kNumHeadJoints; ++j) d.parents[j] = static_cast<int>(kintree[j]);
  const auto& f = in.Get("f", {-1, 3}, true);
  d.faces = RowMajorFrom<RowMatrixX3i>(f.ToInt64s(), f.dim(0), 3);
  const auto lf = in.Ints("lmk_faces_idx", {kNumLandmarks});
  d.lmk_faces.resize(kNumLandmarks);
  for (int i = 0; i < kNumLandmarks; ++i) d.lmk_faces[i] = static_cast<int>(lf[i]);
  d.lmk_bary = RowMajorFrom<RowMatrixX3f>(in.Floats("lmk_bary_coords", {kNumLandmarks, 3}), kNumLandmarks, 3);
  if (in.Has("dynamic_lmk_faces_idx") || in.Has("dynamic_lmk_bary_coords")) {
    d.dyn_lmk_faces = RowMajorFrom<Eigen::MatrixXi>(
        in.Ints("dynamic_lmk_faces_idx", {kNumYawBins, kNumContourLandmarks}), kNumYawBins, kNumContourLandmarks);
    d.dyn_lmk_bary =
        RowMajorFrom<Eigen::MatrixXf>(in.Floats("dynamic_lmk_bary_coords", {kNumYawBins, kNumContourLandmarks, 3}),
                                      kNumYawBins * kNumContourLandmarks, 3);
  }
  if (in.Has("vt") || in.Has("ft")) {
    const auto& uv = in.Get("vt", {-1, 2}, false);
    d.uvs = RowMajorFrom<RowMatrixX2f>(uv.ToFloats(), uv.dim(0), 2);
    d.uv_faces = RowMajorFrom<RowMatrixX3i>(in.Ints("ft", {d.faces.rows(), 3}), d.faces.rows(), 3);
  }
  if (in.Has("texture_mean")) {
    const auto& tm = in.Get("texture_mean", {-1, -1, 3}, false);
    d.texture_height = static_cast<int>(tm.dim(0));
    d.texture_width = static_cast<int>(tm.dim(1));
    d.texture_mean = tm.ToFloats();
    if (in.Has("texture_basis")) {
      const auto& tb = in.Get("texture_basis", {tm.dim(0), tm.dim(1), 3, -1}, false);
      d.texture_basis = BasisFromNK3(tb.ToFloats(), tm.dim(0) * tm.dim(1), tb.dim(3));
    }
  }
  const auto name = in.Strings("name");
  d.name = name.empty() ? "unnamed" : name[0];
  const auto description = in.Strings("description");
  for (size_t i = 0; i < description.size(); ++i) d.description += (i ? " " : "") + description[i];
  d.shape_names = in.Strings("shape_names");
  d.expression_names = in.Strings("expression_names");
  d.texture_names = in.Strings("texture_names");
  if (in.Has("expression_range")) {
    const std::vector<float> range = in.Get("expression_range", {2}, false).ToFloats();
    d.expression_min = range[0];
    d.expression_max = range[1];
  }
  try {
    return HeadModel(std::move(d));
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

namespace {

// The basis as int16 multiples of `step` plus KEY_step; refuses a step too
// fine for int16 rather than wrapping.
void PutCompactBasis(NpzArchive* a, const std::string& key, const Eigen::MatrixXf& basis, int64_t n, double step) {
  const std::vector<float> values = BasisToNK3(basis);
  std::vector<int16_t> steps(values.size());
  for (size_t i = 0; i < values.size(); ++i) {
    const double q = std::round(values[i] / step);
    if (std::abs(q) > 32767)
      throw std::invalid_argument(key + ": a value of " + std::to_string(values[i]) + " m needs a step of at least " +
                                  std::to_string(std::abs(values[i]) / 32767) + " m for int16");
    steps[i] = static_cast<int16_t>(q);
  }
  (*a)[key] = NpyArray::From<int16_t>({n, 3, basis.cols()}, steps.data());
  const float step_value = static_cast<float>(step);
  (*a)[key + "_step"] = NpyArray::From<float>({1}, &step_value);
}

}  // namespace

void SaveHeadModel(const HeadModel& model, const std::string& path, const HeadModelSaveOptions& options) {
  if (!(options.basis_step >= 0) || !std::isfinite(options.basis_step))
    throw std::invalid_argument("basis step must be 0 (float32) or a positive number of metres");
  const HeadModelData& d = model.data();
  const int64_t n = model.num_vertices();
  NpzArchive a;
  const int32_t version = kHeadModelFormatVersion;
  a["headcast_format"] = NpyArray::From<int32_t>({1}, &version);
  a["v_template"] = NpyArray::From<float>({n, 3}, RowMajorValues<float>(d.v_template).data());
  if (options.basis_step > 0) {
    PutCompactBasis(&a, "shapedirs", d.shapedirs, n, options.basis_step);
    PutCompactBasis(&a, "expressiondirs", d.expressiondirs, n, options.basis_step);
  } else {
    a["shapedirs"] = NpyArray::From<float>({n, 3, model.num_shape()}, BasisToNK3(d.shapedirs).data());
    a["expressiondirs"] = NpyArray::From<float>({n, 3, model.num_expression()}, BasisToNK3(d.expressiondirs).data());
  }
  if (d.posedirs.size() > 0)
    a["posedirs"] = NpyArray::From<float>({n, 3, kNumPoseFeatures}, BasisToNK3(d.posedirs).data());
  a["J_regressor"] = NpyArray::From<float>({kNumHeadJoints, n}, RowMajorValues<float>(d.j_regressor).data());
  a["weights"] = NpyArray::From<float>({n, kNumHeadJoints}, RowMajorValues<float>(d.weights).data());
  std::vector<int32_t> kintree(2 * kNumHeadJoints);
  for (int j = 0; j < kNumHeadJoints; ++j) {
    kintree[j] = d.parents[j];
    kintree[kNumHeadJoints + j] = j;
  }
  a["kintree_table"] = NpyArray::From<int32_t>({2, kNumHeadJoints}, kintree.data());
  a["f"] = NpyArray::From<int32_t>({model.num_faces(), 3}, RowMajorValues<int32_t>(d.faces).data());
  a["lmk_faces_idx"] =
      NpyArray::From<int32_t>({kNumLandmarks}, RowMajorValues<int32_t>(Eigen::MatrixXi(d.lmk_faces)).data());
  a["lmk_bary_coords"] = NpyArray::From<float>({kNumLandmarks, 3}, RowMajorValues<float>(d.lmk_bary).data());
  if (d.dyn_lmk_faces.size() > 0) {
    a["dynamic_lmk_faces_idx"] =
        NpyArray::From<int32_t>({kNumYawBins, kNumContourLandmarks}, RowMajorValues<int32_t>(d.dyn_lmk_faces).data());
    a["dynamic_lmk_bary_coords"] =
        NpyArray::From<float>({kNumYawBins, kNumContourLandmarks, 3}, RowMajorValues<float>(d.dyn_lmk_bary).data());
  }
  if (d.uvs.rows() > 0) {
    a["vt"] = NpyArray::From<float>({d.uvs.rows(), 2}, RowMajorValues<float>(d.uvs).data());
    a["ft"] = NpyArray::From<int32_t>({d.uv_faces.rows(), 3}, RowMajorValues<int32_t>(d.uv_faces).data());
  }
  if (!d.texture_mean.empty()) {
    a["texture_mean"] = NpyArray::From<float>({d.texture_height, d.texture_width, 3}, d.texture_mean.data());
    if (d.texture_basis.size() > 0)
      a["texture_basis"] = NpyArray::From<float>({d.texture_height, d.texture_width, 3, d.texture_basis.cols()},
                                                 BasisToNK3(d.texture_basis).data());
  }
  a["name"] = StringsToNpy({d.name});
  if (!d.description.empty()) a["description"] = StringsToNpy({d.description});
  if (!d.shape_names.empty()) a["shape_names"] = StringsToNpy(d.shape_names);
  if (!d.expression_names.empty()) a["expression_names"] = StringsToNpy(d.expression_names);
  if (!d.texture_names.empty()) a["texture_names"] = StringsToNpy(d.texture_names);
  if (d.HasExpressionRange()) {
    const float range[2] = {d.expression_min, d.expression_max};
    a["expression_range"] = NpyArray::From<float>({2}, range);
  }
  WriteNpz(path, a);
}

HeadModel LoadHeadModelSpec(const std::string& spec) {
  if (spec == "builtin") return MakeBuiltinHead();
  return LoadHeadModel(spec);
}

}  // namespace headcast
