// NumPy .npy/.npz reading and writing for the dtypes headcast exchanges with Python tools.
#pragma once

#include <algorithm>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace headcast {

// The element types we accept: little-endian, C order. Anything else is refused.
enum class DType { kFloat32, kFloat64, kInt16, kInt32, kInt64, kUInt8, kBool };

const char* DTypeName(DType dtype);
int DTypeSize(DType dtype);

// The most bytes one array may hold: far above any head model or avatar, far
// below what a forged shape could ask a machine for.
constexpr int64_t kMaxNpyBytes = int64_t(1) << 32;

// A dense N-d array as stored in a .npy file: element type, shape, raw bytes.
class NpyArray {
 public:
  NpyArray() = default;
  // Zero-filled array of the given type and shape; throws std::invalid_argument
  // on a negative dimension or more than kMaxNpyBytes.
  NpyArray(DType dtype, std::vector<int64_t> shape);

  template <typename T>
  static NpyArray From(std::vector<int64_t> shape, const T* values);

  DType dtype() const { return dtype_; }
  const std::vector<int64_t>& shape() const { return shape_; }
  int ndim() const { return static_cast<int>(shape_.size()); }
  int64_t dim(int i) const { return shape_.at(i); }
  int64_t size() const;
  const std::vector<uint8_t>& bytes() const { return bytes_; }
  std::vector<uint8_t>& mutable_bytes() { return bytes_; }

  // Typed access; throws if T does not match the stored dtype.
  template <typename T>
  const T* data() const;
  template <typename T>
  T* mutable_data();

  // Any numeric/bool dtype converted element-wise.
  std::vector<double> ToDoubles() const;
  std::vector<float> ToFloats() const;
  std::vector<int64_t> ToInt64s() const;

  std::string ShapeString() const;  // "(3, 4)"

 private:
  DType dtype_ = DType::kFloat32;
  std::vector<int64_t> shape_;
  std::vector<uint8_t> bytes_;
};

template <typename T>
struct DTypeOf;
template <>
struct DTypeOf<float> {
  static constexpr DType value = DType::kFloat32;
};
template <>
struct DTypeOf<double> {
  static constexpr DType value = DType::kFloat64;
};
template <>
struct DTypeOf<int16_t> {
  static constexpr DType value = DType::kInt16;
};
template <>
struct DTypeOf<int32_t> {
  static constexpr DType value = DType::kInt32;
};
template <>
struct DTypeOf<int64_t> {
  static constexpr DType value = DType::kInt64;
};
template <>
struct DTypeOf<uint8_t> {
  static constexpr DType value = DType::kUInt8;
};
template <>
struct DTypeOf<bool> {
  static constexpr DType value = DType::kBool;
};

template <typename T>
const T* NpyArray::data() const {
  if (dtype_ != DTypeOf<T>::value)
    throw std::runtime_error(std::string("array holds ") + DTypeName(dtype_) + ", not " + DTypeName(DTypeOf<T>::value));
  return reinterpret_cast<const T*>(bytes_.data());
}
template <typename T>
T* NpyArray::mutable_data() {
  return const_cast<T*>(static_cast<const NpyArray*>(this)->data<T>());
}

template <typename T>
NpyArray NpyArray::From(std::vector<int64_t> shape, const T* values) {
  NpyArray a(DTypeOf<T>::value, std::move(shape));
  if (a.size() > 0) std::copy_n(values, a.size(), a.mutable_data<T>());
  return a;
}

// `what` names the source (file, or file:key) in error messages.
NpyArray ParseNpy(const std::string& bytes, const std::string& what);
std::string SerializeNpy(const NpyArray& array);

NpyArray ReadNpy(const std::string& path);
void WriteNpy(const std::string& path, const NpyArray& array);

// An .npz archive: key (file name without ".npy") to array.
using NpzArchive = std::map<std::string, NpyArray>;

// Throws std::runtime_error naming the file (and key) on any problem:
// missing file, not a zip, truncated entry, unsupported dtype or order.
NpzArchive ReadNpz(const std::string& path);
// Written to a temporary file and renamed, so readers never see half a file.
void WriteNpz(const std::string& path, const NpzArchive& archive, bool compress = true);

// Strings travel in npz files as uint8 arrays of UTF-8 text, one item per line.
NpyArray StringsToNpy(const std::vector<std::string>& items);
std::vector<std::string> NpyToStrings(const NpyArray& array);

}  // namespace headcast
