// Mesh files and mesh checks.
#include "common/headmodel/mesh_io.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <vector>

namespace headcast {
namespace {

[[noreturn]] void Fail(const std::string& path, const std::string& what) {
  throw std::runtime_error(path + ": " + what);
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::string Extension(const std::string& path) {
  const auto dot = path.find_last_of('.');
  return dot == std::string::npos ? "" : Lower(path.substr(dot + 1));
}

struct MeshBuilder {
  std::vector<float> xyz;
  std::vector<int> tri;
  void AddPolygon(const std::vector<long long>& idx, long long num_vertices, const std::string& path,
                  const std::string& where) {
    if (idx.size() < 3) Fail(path, where + ": a face needs at least 3 vertices, has " + std::to_string(idx.size()));
    for (long long i : idx)
      if (i < 0 || i >= num_vertices)
        Fail(path, where + ": vertex index " + std::to_string(i) + " out of range (the mesh has " +
                       std::to_string(num_vertices) + " vertices)");
    for (size_t k = 1; k + 1 < idx.size(); ++k) {
      tri.push_back(static_cast<int>(idx[0]));
      tri.push_back(static_cast<int>(idx[k]));
      tri.push_back(static_cast<int>(idx[k + 1]));
    }
  }
  void AddVertex(double x, double y, double z, const std::string& path, const std::string& where) {
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
      Fail(path, where + ": vertex " + std::to_string(xyz.size() / 3) + " has a non-finite coordinate");
    xyz.push_back(static_cast<float>(x));
    xyz.push_back(static_cast<float>(y));
    xyz.push_back(static_cast<float>(z));
  }
  TriangleMesh Build(const std::string& path) const {
    if (xyz.empty()) Fail(path, "the mesh has no vertices");
    if (tri.empty()) Fail(path, "the mesh has no faces");
    TriangleMesh m;
    m.vertices = Eigen::Map<const RowMatrixX3f>(xyz.data(), static_cast<Eigen::Index>(xyz.size() / 3), 3);
    m.faces = Eigen::Map<const RowMatrixX3i>(tri.data(), static_cast<Eigen::Index>(tri.size() / 3), 3);
    return m;
  }
};

TriangleMesh ReadObj(const std::string& path, std::istream& in) {
  MeshBuilder b;
  std::string line;
  std::vector<std::pair<int, std::vector<long long>>> faces;  // (line number, raw indices)
  for (int number = 1; std::getline(in, line); ++number) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    const std::string where = "line " + std::to_string(number);
    if (tag == "v") {
      // strtod, unlike operator>>, reads "nan" and "inf": they must reach the finiteness check.
      double xyz[3];
      for (double& value : xyz) {
        std::string token;
        char* end = nullptr;
        if (!(ls >> token) || (value = std::strtod(token.c_str(), &end), *end != '\0'))
          Fail(path, where + ": a vertex needs three numbers");
      }
      b.AddVertex(xyz[0], xyz[1], xyz[2], path, where);
    } else if (tag == "f") {
      std::vector<long long> idx;
      for (std::string item; ls >> item;) {
        long long i = 0;
        try {
          i = std::stoll(item.substr(0, item.find('/')));
        } catch (const std::exception&) {
          Fail(path, where + ": bad face index '" + item + "'");
        }
        if (i == 0) Fail(path, where + ": face index 0 (OBJ indices start at 1)");
        idx.push_back(i);
      }
      faces.emplace_back(number, std::move(idx));
    }
  }
  const long long n = static_cast<long long>(b.xyz.size() / 3);
  for (auto& [number, idx] : faces) {
    for (auto& i : idx) i = i > 0 ? i - 1 : n + i;  // negative: relative to the end
    b.AddPolygon(idx, n, path, "line " + std::to_string(number));
  }
  return b.Build(path);
}

// PLY scalar types and a reader for one value of each.
enum class PlyType { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64 };

PlyType ParsePlyType(const std::string& t, const std::string& path) {
  static const std::map<std::string, PlyType> types = {
      {"char", PlyType::kInt8},      {"int8", PlyType::kInt8},       {"uchar", PlyType::kUInt8},
      {"uint8", PlyType::kUInt8},    {"short", PlyType::kInt16},     {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUInt16},  {"uint16", PlyType::kUInt16},   {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},    {"uint", PlyType::kUInt32},     {"uint32", PlyType::kUInt32},
      {"float", PlyType::kFloat32},  {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64}};
  auto it = types.find(t);
  if (it == types.end()) Fail(path, "unknown PLY property type '" + t + "'");
  return it->second;
}

int PlySize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUInt8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUInt16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUInt32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  bool is_list = false;
  PlyType count_type = PlyType::kUInt8, type = PlyType::kFloat32;
};
struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
};

class PlyValueReader {
 public:
  PlyValueReader(std::istream& in, int format, const std::string& path) : in_(in), format_(format), path_(path) {}
  double Read(PlyType t) {
    if (format_ == 0) {
      double v;
      if (!(in_ >> v)) Fail(path_, "PLY data is truncated or not a number");
      return v;
    }
    unsigned char raw[8];
    const int n = PlySize(t);
    if (!in_.read(reinterpret_cast<char*>(raw), n)) Fail(path_, "PLY data is truncated");
    if ((format_ == 2) != kBigEndianHost) std::reverse(raw, raw + n);
    switch (t) {
      case PlyType::kInt8:
        return static_cast<int8_t>(raw[0]);
      case PlyType::kUInt8:
        return raw[0];
      case PlyType::kInt16:
        return Cast<int16_t>(raw);
      case PlyType::kUInt16:
        return Cast<uint16_t>(raw);
      case PlyType::kInt32:
        return Cast<int32_t>(raw);
      case PlyType::kUInt32:
        return Cast<uint32_t>(raw);
      case PlyType::kFloat32:
        return Cast<float>(raw);
      case PlyType::kFloat64:
        return Cast<double>(raw);
    }
    return 0;
  }

 private:
  template <typename T>
  static double Cast(const unsigned char* raw) {
    T v;
    std::memcpy(&v, raw, sizeof(T));
    return static_cast<double>(v);
  }
  static constexpr bool kBigEndianHost = (__BYTE_ORDER__ == __ORDER_BIG_ENDIAN__);
  std::istream& in_;
  int format_;  // 0 ascii, 1 little endian, 2 big endian
  const std::string& path_;
};

TriangleMesh ReadPly(const std::string& path, std::istream& in) {
  std::string line;
  if (!std::getline(in, line) || line.rfind("ply", 0) != 0) Fail(path, "not a PLY file (no 'ply' magic)");
  int format = -1;
  std::vector<PlyElement> elements;
  for (;;) {
    if (!std::getline(in, line)) Fail(path, "PLY header has no end_header");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "format") {
      std::string f;
      ls >> f;
      if (f == "ascii")
        format = 0;
      else if (f == "binary_little_endian")
        format = 1;
      else if (f == "binary_big_endian")
        format = 2;
      else
        Fail(path, "unknown PLY format '" + f + "'");
    } else if (key == "element") {
      PlyElement e;
      if (!(ls >> e.name >> e.count) || e.count < 0) Fail(path, "bad PLY element line '" + line + "'");
      elements.push_back(e);
    } else if (key == "property") {
      if (elements.empty()) Fail(path, "PLY property before any element");
      PlyProperty p;
      std::string t;
      ls >> t;
      if (t == "list") {
        std::string ct, vt;
        ls >> ct >> vt >> p.name;
        p.is_list = true;
        p.count_type = ParsePlyType(ct, path);
        p.type = ParsePlyType(vt, path);
      } else {
        p.type = ParsePlyType(t, path);
        ls >> p.name;
      }
      elements.back().properties.push_back(p);
    } else if (key == "end_header") {
      break;
    }
  }
  if (format < 0) Fail(path, "PLY header has no format line");
  PlyValueReader reader(in, format, path);
  MeshBuilder b;
  long long num_vertices = 0;
  std::vector<std::vector<long long>> polygons;
  for (const PlyElement& e : elements) {
    int ix = -1, iy = -1, iz = -1, iface = -1;
    for (size_t k = 0; k < e.properties.size(); ++k) {
      const std::string& n = e.properties[k].name;
      if (n == "x") ix = static_cast<int>(k);
      if (n == "y") iy = static_cast<int>(k);
      if (n == "z") iz = static_cast<int>(k);
      if ((n == "vertex_indices" || n == "vertex_index") && e.properties[k].is_list) iface = static_cast<int>(k);
    }
    const bool vertex = e.name == "vertex", face = e.name == "face";
    if (vertex && (ix < 0 || iy < 0 || iz < 0)) Fail(path, "PLY vertex element lacks x, y or z");
    if (face && iface < 0) Fail(path, "PLY face element lacks a vertex_indices list");
    if (vertex) num_vertices = e.count;
    std::vector<double> values(e.properties.size());
    for (long long r = 0; r < e.count; ++r) {
      std::vector<long long> idx;
      for (size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& p = e.properties[k];
        if (!p.is_list) {
          values[k] = reader.Read(p.type);
          continue;
        }
        const double count = reader.Read(p.count_type);
        if (count < 0 || count > 1e6) Fail(path, "PLY list of " + std::to_string(count) + " entries");
        for (int j = 0; j < static_cast<int>(count); ++j) {
          const double v = reader.Read(p.type);
          if (static_cast<int>(k) == iface) idx.push_back(static_cast<long long>(v));
        }
      }
      if (vertex) b.AddVertex(values[ix], values[iy], values[iz], path, "vertex " + std::to_string(r));
      if (face) polygons.push_back(std::move(idx));
    }
  }
  for (size_t f = 0; f < polygons.size(); ++f)
    b.AddPolygon(polygons[f], num_vertices, path, "face " + std::to_string(f));
  return b.Build(path);
}

uint64_t EdgeKey(int a, int b) {
  if (a > b) std::swap(a, b);
  return (static_cast<uint64_t>(a) << 32) | static_cast<uint32_t>(b);
}

}  // namespace

TriangleMesh ReadMesh(const std::string& path) {
  const std::string ext = Extension(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) Fail(path, "cannot open");
  if (ext == "obj") return ReadObj(path, in);
  if (ext == "ply") return ReadPly(path, in);
  Fail(path, "unknown mesh format '." + ext + "' (OBJ and PLY are read)");
}

void WriteMesh(const std::string& path, const TriangleMesh& mesh) {
  const std::string ext = Extension(path);
  std::ofstream out(path);
  if (!out) Fail(path, "cannot write");
  out.precision(9);
  if (ext == "obj") {
    for (Eigen::Index i = 0; i < mesh.vertices.rows(); ++i)
      out << "v " << mesh.vertices(i, 0) << ' ' << mesh.vertices(i, 1) << ' ' << mesh.vertices(i, 2) << '\n';
    for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f)
      out << "f " << mesh.faces(f, 0) + 1 << ' ' << mesh.faces(f, 1) + 1 << ' ' << mesh.faces(f, 2) + 1 << '\n';
  } else if (ext == "ply") {
    out << "ply\nformat ascii 1.0\nelement vertex " << mesh.vertices.rows()
        << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << mesh.faces.rows()
        << "\nproperty list uchar int vertex_indices\nend_header\n";
    for (Eigen::Index i = 0; i < mesh.vertices.rows(); ++i)
      out << mesh.vertices(i, 0) << ' ' << mesh.vertices(i, 1) << ' ' << mesh.vertices(i, 2) << '\n';
    for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f)
      out << "3 " << mesh.faces(f, 0) << ' ' << mesh.faces(f, 1) << ' ' << mesh.faces(f, 2) << '\n';
  } else {
    Fail(path, "unknown mesh format '." + ext + "' (OBJ and PLY are written)");
  }
  if (!out) Fail(path, "write failed");
}

MeshDiagnostics Diagnose(const TriangleMesh& mesh) {
  MeshDiagnostics d;
  const int n = static_cast<int>(mesh.vertices.rows());
  std::unordered_map<uint64_t, int> edge_faces;
  std::vector<char> used(n, 0);
  for (Eigen::Index f = 0; f < mesh.faces.rows(); ++f) {
    const int a = mesh.faces(f, 0), b = mesh.faces(f, 1), c = mesh.faces(f, 2);
    if (a == b || b == c || a == c) {
      ++d.degenerate_faces;
      continue;
    }
    const Eigen::Vector3f e1 = mesh.vertices.row(b) - mesh.vertices.row(a);
    const Eigen::Vector3f e2 = mesh.vertices.row(c) - mesh.vertices.row(a);
    if (e1.cross(e2).norm() == 0) ++d.degenerate_faces;
    used[a] = used[b] = used[c] = 1;
    ++edge_faces[EdgeKey(a, b)];
    ++edge_faces[EdgeKey(b, c)];
    ++edge_faces[EdgeKey(c, a)];
  }
  for (const auto& [key, count] : edge_faces)
    if (count > 2) ++d.non_manifold_edges;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo, sum = Eigen::Vector3d::Zero();
  int referenced = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d v = mesh.vertices.row(i).cast<double>().transpose();
    if (!v.allFinite()) {
      ++d.non_finite_vertices;
      continue;
    }
    if (!used[i]) {
      ++d.unreferenced_vertices;
      continue;
    }
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
    sum += v;
    ++referenced;
  }
  if (referenced > 0) {
    d.bounding_diagonal = (hi - lo).norm();
    const Eigen::Vector3d centroid = sum / referenced;
    double ss = 0;
    for (int i = 0; i < n; ++i)
      if (used[i] && mesh.vertices.row(i).allFinite())
        ss += (mesh.vertices.row(i).cast<double>().transpose() - centroid).squaredNorm();
    d.rms_radius = std::sqrt(ss / referenced);
  }
  return d;
}

TriangleMesh SubdivideMidpoints(const TriangleMesh& mesh) {
  std::vector<Eigen::Vector3f> v;
  for (Eigen::Index i = 0; i < mesh.vertices.rows(); ++i) v.push_back(mesh.vertices.row(i).transpose());
  std::unordered_map<uint64_t, int> midpoint;
  auto mid = [&](int a, int b) {
    auto [it, fresh] = midpoint.emplace(EdgeKey(a, b), static_cast<int>(v.size()));
    if (fresh) v.push_back(0.5f * (v[a] + v[b]));
    return it->second;
  };
  std::vector<Eigen::Vector3i> f;
  for (Eigen::Index k = 0; k < mesh.faces.rows(); ++k) {
    const int a = mesh.faces(k, 0), b = mesh.faces(k, 1), c = mesh.faces(k, 2);
    const int ab = mid(a, b), bc = mid(b, c), ca = mid(c, a);
    f.emplace_back(a, ab, ca);
    f.emplace_back(ab, b, bc);
    f.emplace_back(ca, bc, c);
    f.emplace_back(ab, bc, ca);
  }
  TriangleMesh out;
  out.vertices.resize(static_cast<Eigen::Index>(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) out.vertices.row(static_cast<Eigen::Index>(i)) = v[i].transpose();
  out.faces.resize(static_cast<Eigen::Index>(f.size()), 3);
  for (size_t i = 0; i < f.size(); ++i) out.faces.row(static_cast<Eigen::Index>(i)) = f[i].transpose();
  return out;
}

TriangleMesh ClusterDecimate(const TriangleMesh& mesh, double cell) {
  if (!(cell > 0)) throw std::invalid_argument("ClusterDecimate: cell must be positive");
  std::map<std::array<long long, 3>, int> cluster_of_cell;
  std::vector<int> cluster(mesh.vertices.rows());
  std::vector<Eigen::Vector3d> sum;
  std::vector<int> count;
  for (Eigen::Index i = 0; i < mesh.vertices.rows(); ++i) {
    std::array<long long, 3> key;
    for (int c = 0; c < 3; ++c) key[c] = static_cast<long long>(std::floor(mesh.vertices(i, c) / cell));
    auto [it, fresh] = cluster_of_cell.emplace(key, static_cast<int>(sum.size()));
    if (fresh) {
      sum.emplace_back(Eigen::Vector3d::Zero());
      count.push_back(0);
    }
    cluster[i] = it->second;
    sum[it->second] += mesh.vertices.row(i).cast<double>().transpose();
    ++count[it->second];
  }
  std::unordered_map<uint64_t, int> edge_faces;
  std::vector<Eigen::Vector3i> faces;
  std::unordered_map<uint64_t, char> seen_face;
  for (Eigen::Index k = 0; k < mesh.faces.rows(); ++k) {
    const int a = cluster[mesh.faces(k, 0)], b = cluster[mesh.faces(k, 1)], c = cluster[mesh.faces(k, 2)];
    if (a == b || b == c || a == c) continue;
    // The same cluster triangle from several original faces: keep one.
    std::array<int, 3> s = {a, b, c};
    std::sort(s.begin(), s.end());
    const uint64_t face_key = (static_cast<uint64_t>(s[0]) * 1000003ull + s[1]) * 1000003ull + s[2];
    if (!seen_face.emplace(face_key, 1).second) continue;
    if (edge_faces[EdgeKey(a, b)] >= 2 || edge_faces[EdgeKey(b, c)] >= 2 || edge_faces[EdgeKey(c, a)] >= 2) continue;
    ++edge_faces[EdgeKey(a, b)];
    ++edge_faces[EdgeKey(b, c)];
    ++edge_faces[EdgeKey(c, a)];
    faces.emplace_back(a, b, c);
  }
  // Keep only clusters some face uses, renumbered.
  std::vector<int> remap(sum.size(), -1);
  int next = 0;
  for (auto& f : faces)
    for (int c = 0; c < 3; ++c) {
      if (remap[f[c]] < 0) remap[f[c]] = next++;
      f[c] = remap[f[c]];
    }
  TriangleMesh out;
  out.vertices.resize(next, 3);
  for (size_t k = 0; k < sum.size(); ++k)
    if (remap[k] >= 0) out.vertices.row(remap[k]) = (sum[k] / count[k]).cast<float>().transpose();
  out.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t i = 0; i < faces.size(); ++i) out.faces.row(static_cast<Eigen::Index>(i)) = faces[i].transpose();
  return out;
}

}  // namespace headcast
