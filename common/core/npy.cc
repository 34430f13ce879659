// NumPy .npy/.npz reading and writing (npz through libzip).
#include "common/core/npy.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "common/core/check.h"
#include "common/core/zip_archive.h"

namespace headcast {
namespace {

struct DTypeInfo {
  DType dtype;
  const char* descr;
  int size;
  const char* name;
};

constexpr DTypeInfo kDTypes[] = {
    {DType::kFloat32, "<f4", 4, "float32"}, {DType::kFloat64, "<f8", 8, "float64"}, {DType::kInt16, "<i2", 2, "int16"},
    {DType::kInt32, "<i4", 4, "int32"},     {DType::kInt64, "<i8", 8, "int64"},     {DType::kUInt8, "|u1", 1, "uint8"},
    {DType::kBool, "|b1", 1, "bool"},
};

const DTypeInfo& Info(DType dtype) {
  for (const auto& i : kDTypes)
    if (i.dtype == dtype) return i;
  HEADCAST_CHECK(false) << "dtype " << static_cast<int>(dtype) << " missing from kDTypes";
  return kDTypes[0];
}

[[noreturn]] void Fail(const std::string& what, const std::string& why) { throw std::runtime_error(what + ": " + why); }

// Bytes of an array of `shape`, or -1 when a dimension is negative or the
// product passes `limit` (checked before multiplying, so it cannot wrap).
int64_t ArrayBytes(const std::vector<int64_t>& shape, int element_size, int64_t limit) {
  for (int64_t d : shape)
    if (d < 0) return -1;
  // An empty array needs no bytes whatever its other dimensions (the
  // running product would otherwise outgrow a small limit first).
  if (std::find(shape.begin(), shape.end(), 0) != shape.end()) return 0;
  int64_t n = element_size;
  for (int64_t d : shape) {
    if (n > limit / d) return -1;
    n *= d;
  }
  return n <= limit ? n : -1;
}

// Value of `key` in the header dict, as the raw text up to the next top-level comma.
std::string HeaderField(const std::string& header, const std::string& key, const std::string& what) {
  const std::string quoted = "'" + key + "'";
  auto pos = header.find(quoted);
  if (pos == std::string::npos) Fail(what, "npy header has no '" + key + "' field");
  pos = header.find(':', pos + quoted.size());
  if (pos == std::string::npos) Fail(what, "malformed npy header");
  ++pos;
  while (pos < header.size() && header[pos] == ' ') ++pos;
  if (pos < header.size() && header[pos] == '(') {
    auto end = header.find(')', pos);
    if (end == std::string::npos) Fail(what, "malformed shape in npy header");
    return header.substr(pos, end - pos + 1);
  }
  auto end = header.find_first_of(",}", pos);
  if (end == std::string::npos) Fail(what, "malformed npy header");
  std::string value = header.substr(pos, end - pos);
  while (!value.empty() && value.back() == ' ') value.pop_back();
  return value;
}

}  // namespace

const char* DTypeName(DType dtype) { return Info(dtype).name; }
int DTypeSize(DType dtype) { return Info(dtype).size; }

NpyArray::NpyArray(DType dtype, std::vector<int64_t> shape) : dtype_(dtype), shape_(std::move(shape)) {
  for (int64_t d : shape_)
    if (d < 0) throw std::invalid_argument("NpyArray: negative dimension");
  const int64_t bytes = ArrayBytes(shape_, DTypeSize(dtype_), kMaxNpyBytes);
  if (bytes < 0) throw std::invalid_argument("NpyArray: shape " + ShapeString() + " is larger than any array we hold");
  bytes_.assign(static_cast<size_t>(bytes), 0);
}

int64_t NpyArray::size() const {
  int64_t n = 1;
  for (int64_t d : shape_) n *= d;
  return n;
}

std::string NpyArray::ShapeString() const {
  std::string s = "(";
  for (size_t i = 0; i < shape_.size(); ++i) {
    if (i) s += ", ";
    s += std::to_string(shape_[i]);
  }
  if (shape_.size() == 1) s += ",";
  return s + ")";
}

template <typename Out>
static std::vector<Out> ConvertAll(const NpyArray& a) {
  std::vector<Out> out(a.size());
  const uint8_t* p = a.bytes().data();
  for (int64_t i = 0; i < a.size(); ++i) {
    switch (a.dtype()) {
      case DType::kFloat32: {
        float v;
        std::memcpy(&v, p + 4 * i, 4);
        out[i] = static_cast<Out>(v);
        break;
      }
      case DType::kFloat64: {
        double v;
        std::memcpy(&v, p + 8 * i, 8);
        out[i] = static_cast<Out>(v);
        break;
      }
      case DType::kInt16: {
        int16_t v;
        std::memcpy(&v, p + 2 * i, 2);
        out[i] = static_cast<Out>(v);
        break;
      }
      case DType::kInt32: {
        int32_t v;
        std::memcpy(&v, p + 4 * i, 4);
        out[i] = static_cast<Out>(v);
        break;
      }
      case DType::kInt64: {
        int64_t v;
        std::memcpy(&v, p + 8 * i, 8);
        out[i] = static_cast<Out>(v);
        break;
      }
      case DType::kUInt8:
        out[i] = static_cast<Out>(p[i]);
        break;
      case DType::kBool:
        out[i] = static_cast<Out>(p[i] != 0);
        break;
    }
  }
  return out;
}

std::vector<double> NpyArray::ToDoubles() const { return ConvertAll<double>(*this); }
std::vector<float> NpyArray::ToFloats() const { return ConvertAll<float>(*this); }
std::vector<int64_t> NpyArray::ToInt64s() const { return ConvertAll<int64_t>(*this); }

NpyArray ParseNpy(const std::string& bytes, const std::string& what) {
  static const char kMagic[] = "\x93NUMPY";
  if (bytes.size() < 10 || bytes.compare(0, 6, kMagic, 6) != 0) Fail(what, "not an .npy array (bad magic)");
  const int major = static_cast<uint8_t>(bytes[6]);
  size_t header_len = 0, offset = 0;
  if (major == 1) {
    header_len = static_cast<uint8_t>(bytes[8]) | (static_cast<uint8_t>(bytes[9]) << 8);
    offset = 10;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) Fail(what, "truncated npy header");
    header_len = 0;
    for (int i = 0; i < 4; ++i) header_len |= static_cast<size_t>(static_cast<uint8_t>(bytes[8 + i])) << (8 * i);
    offset = 12;
  } else {
    Fail(what, "unsupported npy format version " + std::to_string(major));
  }
  if (bytes.size() < offset + header_len) Fail(what, "truncated npy header");
  const std::string header = bytes.substr(offset, header_len);
  offset += header_len;

  std::string descr = HeaderField(header, "descr", what);
  if (descr.size() < 2 || (descr.front() != '\'' && descr.front() != '"'))
    Fail(what, "unsupported dtype " + descr + " (structured arrays are not supported)");
  descr = descr.substr(1, descr.size() - 2);
  if (descr == "<u1" || descr == "=u1") descr = "|u1";
  if (descr == "<b1" || descr == "=b1") descr = "|b1";
  const DTypeInfo* info = nullptr;
  for (const auto& i : kDTypes)
    if (descr == i.descr) info = &i;
  if (!info)
    Fail(what,
         "unsupported dtype '" + descr + "' (expected little-endian float32/float64/int16/int32/int64/uint8/bool)");
  if (HeaderField(header, "fortran_order", what) != "False")
    Fail(what, "Fortran-ordered arrays are not supported; save with C order");

  std::vector<int64_t> shape;
  std::string shape_text = HeaderField(header, "shape", what);
  if (shape_text.size() < 2 || shape_text.front() != '(') Fail(what, "malformed shape " + shape_text);
  std::stringstream ss(shape_text.substr(1, shape_text.size() - 2));
  std::string item;
  while (std::getline(ss, item, ',')) {
    item.erase(0, item.find_first_not_of(' '));
    if (item.empty()) continue;
    try {
      size_t used = 0;
      long long d = std::stoll(item, &used);
      if (d < 0) throw std::invalid_argument("negative");
      shape.push_back(d);
    } catch (const std::exception&) {
      Fail(what, "malformed shape " + shape_text);
    }
  }
  // The claim is checked against the bytes present before anything is allocated for it.
  const int64_t present = static_cast<int64_t>(bytes.size() - offset);
  const int64_t need = ArrayBytes(shape, info->size, present);
  if (need < 0)
    Fail(what, "truncated data: shape " + shape_text + " of " + info->name + " needs more than the " +
                   std::to_string(present) + " bytes present");
  NpyArray array(info->dtype, shape);
  std::memcpy(array.mutable_bytes().data(), bytes.data() + offset, static_cast<size_t>(need));
  return array;
}

std::string SerializeNpy(const NpyArray& array) {
  std::string header = std::string("{'descr': '") + Info(array.dtype()).descr +
                       "', 'fortran_order': False, 'shape': " + array.ShapeString() + ", }";
  // Pad so the data starts on a 64-byte boundary, as numpy does.
  const size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header.push_back('\n');
  std::string out("\x93NUMPY\x01\x00", 8);
  out.push_back(static_cast<char>(header.size() & 0xff));
  out.push_back(static_cast<char>((header.size() >> 8) & 0xff));
  out += header;
  out.append(reinterpret_cast<const char*>(array.bytes().data()), array.bytes().size());
  return out;
}

NpyArray ReadNpy(const std::string& path) { return ParseNpy(ReadFileBytes(path), path); }

void WriteNpy(const std::string& path, const NpyArray& array) { WriteFileAtomically(path, SerializeNpy(array)); }

NpzArchive ReadNpz(const std::string& path) {
  NpzArchive archive;
  for (const auto& [name, bytes] : ReadZip(path)) {
    const std::string key =
        name.size() > 4 && name.compare(name.size() - 4, 4, ".npy") == 0 ? name.substr(0, name.size() - 4) : name;
    archive[key] = ParseNpy(bytes, path + ":" + key);
  }
  return archive;
}

void WriteNpz(const std::string& path, const NpzArchive& archive, bool compress) {
  ZipEntries entries;
  for (const auto& [key, array] : archive) entries[key + ".npy"] = SerializeNpy(array);
  WriteZip(path, entries, compress);
}

NpyArray StringsToNpy(const std::vector<std::string>& items) {
  std::string joined;
  for (size_t i = 0; i < items.size(); ++i) {
    if (items[i].find('\n') != std::string::npos) throw std::invalid_argument("string contains a newline");
    joined += items[i];
    if (i + 1 < items.size()) joined += '\n';
  }
  return NpyArray::From<uint8_t>({static_cast<int64_t>(joined.size())},
                                 reinterpret_cast<const uint8_t*>(joined.data()));
}

std::vector<std::string> NpyToStrings(const NpyArray& array) {
  const uint8_t* p = array.data<uint8_t>();
  std::string joined(reinterpret_cast<const char*>(p), array.size());
  std::vector<std::string> items;
  if (joined.empty()) return items;
  std::stringstream ss(joined);
  std::string line;
  while (std::getline(ss, line)) items.push_back(line);
  if (joined.back() == '\n') items.push_back("");
  return items;
}

}  // namespace headcast
