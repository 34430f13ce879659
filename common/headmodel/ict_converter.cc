// ICT-FaceKit conversion.
#include "common/headmodel/ict_converter.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "common/core/options.h"
#include "common/headmodel/head_render.h"

namespace headcast {
namespace fs = std::filesystem;

const std::vector<IctPart>& IctParts() {
  static const std::vector<IctPart> parts = {{"face", 0, 9408},
                                             {"head", 9409, 11247},
                                             {"mouth", 11248, 13293},
                                             {"eyes", 13294, 14061},
                                             {"gums_tongue", 14062, 17038},
                                             {"teeth", 17039, 21450},
                                             {"eyeballs", 21451, 24590},
                                             {"eye_accessories", 24591, 26718}};
  return parts;
}

std::vector<std::string> IctDefaultParts() {
  std::vector<std::string> names;
  for (const IctPart& p : IctParts())
    if (std::string(p.name) != "eye_accessories") names.push_back(p.name);
  return names;
}

const std::vector<int>& IctLandmarkVertices() {
  static const std::vector<int> ids = {
      1225, 1888, 1052, 367,  1719, 1722, 2199, 1447, 966,  3661, 4390, 3927, 3924, 2608, 3272, 4088, 3443,
      268,  493,  1914, 2044, 1401, 3615, 4240, 4114, 2734, 2509, 978,  4527, 4942, 4857, 1140, 2075, 1147,
      4269, 3360, 1507, 1542, 1537, 1528, 1518, 1511, 3742, 3751, 3756, 3721, 3725, 3732, 5708, 5695, 2081,
      0,    4275, 6200, 6213, 6346, 6461, 5518, 5957, 5841, 5702, 5711, 5533, 6216, 6207, 6470, 5517, 5966};
  return ids;
}

void IctConvertOptions::Check() const {
  OptionsCheck c("IctConvertOptions");
  c.NotEmpty("folder", folder).InRange("max_identity", max_identity, 0, 100);
  for (const auto& p : parts) {
    bool known = false;
    for (const auto& q : IctParts()) known |= p == q.name;
    c.That(known, "unknown part '" + p + "' (face, head, mouth, eyes, gums_tongue, teeth, eyeballs, eye_accessories)");
  }
  c.ThrowIfErrors();
}

namespace {

struct ObjMesh {
  std::vector<float> v;                   // 3 per vertex
  std::vector<float> vt;                  // 2 per uv
  std::vector<std::array<int, 3>> f, ft;  // triangles (0-based)
};

// Minimal OBJ reader: v, vt and polygon f lines (v, v/vt, v/vt/vn, v//vn).
ObjMesh ReadObj(const fs::path& path, bool faces) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot open OBJ file");
  ObjMesh m;
  std::string line;
  int line_no = 0;
  auto fail = [&](const std::string& why) {
    throw std::runtime_error(path.string() + ":" + std::to_string(line_no) + ": " + why);
  };
  std::vector<int> poly_v, poly_t;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.size() < 2) continue;
    const char* p = line.c_str();
    if (p[0] == 'v' && p[1] == ' ') {
      float x, y, z;
      if (std::sscanf(p + 2, "%f %f %f", &x, &y, &z) != 3) fail("malformed vertex");
      m.v.insert(m.v.end(), {x, y, z});
    } else if (faces && p[0] == 'v' && p[1] == 't') {
      float u, v;
      if (std::sscanf(p + 3, "%f %f", &u, &v) != 2) fail("malformed texture coordinate");
      m.vt.insert(m.vt.end(), {u, v});
    } else if (faces && p[0] == 'f' && p[1] == ' ') {
      poly_v.clear();
      poly_t.clear();
      std::istringstream ss(line.substr(2));
      std::string tok;
      while (ss >> tok) {
        int vi = 0, ti = 0;
        const auto slash = tok.find('/');
        try {
          vi = std::stoi(tok.substr(0, slash));
          if (slash != std::string::npos && slash + 1 < tok.size() && tok[slash + 1] != '/')
            ti = std::stoi(tok.substr(slash + 1));
        } catch (const std::exception&) {
          fail("malformed face");
        }
        poly_v.push_back(vi - 1);
        poly_t.push_back(ti - 1);
      }
      if (poly_v.size() < 3) fail("face with fewer than 3 vertices");
      for (size_t k = 1; k + 1 < poly_v.size(); ++k) {  // fan triangulation (quads: 2 triangles)
        m.f.push_back({poly_v[0], poly_v[k], poly_v[k + 1]});
        m.ft.push_back({poly_t[0], poly_t[k], poly_t[k + 1]});
      }
    }
  }
  return m;
}

constexpr int kEyeballsPart = 6;  // in IctParts()

// Upstream's eyeLook blendshapes move the lids only; the eyeballs are meant to
// be turned by the application. Skinning each eyeball to its eye joint, pivoting
// at its centre, makes gaze the FLAME way: the eye joints' rotations, which the
// stream and the avatar conditioning already carry. The subject's left eye is +x.
void RigIctEyeballs(const std::vector<int>& remap, HeadModelData* d) {
  const IctPart& eyeballs = IctParts()[kEyeballsPart];
  for (int side = 0; side < 2; ++side) {
    const int joint = side == 0 ? kLeftEyeJoint : kRightEyeJoint;
    std::vector<int> ids;
    for (int i = eyeballs.first; i <= eyeballs.last; ++i)
      if (remap[i] >= 0 && (d->v_template(remap[i], 0) > 0) == (side == 0)) ids.push_back(remap[i]);
    if (ids.empty()) continue;
    // The pivot: the mean of the four extreme vertices along x and y, which on
    // a ball lie on its equator, around its centre. A linear regressor (so it
    // follows the identity), unlike the vertices' centroid not pulled forward
    // by the denser cornea, and unlike the z extremes not pushed back by what
    // the mesh has behind the ball.
    std::vector<int> extremes;
    for (int c = 0; c < 2; ++c) {
      auto [lo, hi] = std::minmax_element(ids.begin(), ids.end(),
                                          [&](int a, int b) { return d->v_template(a, c) < d->v_template(b, c); });
      extremes.push_back(*lo);
      extremes.push_back(*hi);
    }
    d->j_regressor.row(joint).setZero();  // was the face's centroid, as every joint of an unrigged model
    for (int id : extremes) d->j_regressor(joint, id) += 1.0f / extremes.size();
    for (int id : ids) {
      d->weights.row(id).setZero();
      d->weights(id, joint) = 1;
    }
  }
}

// A painted conversion's texture: a swatch of each part's plain colour (its
// triangles all sample the swatch's middle), then the eyeball's colour along
// the angle from its front pole, a ramp its vertices sample by their angle.
constexpr int kSwatch = 8, kRamp = 64, kTextureRows = 4;

// Replaces upstream's texture coordinates (no image comes with them) by the
// painted texture's. `face_part`: each kept face's index in IctParts(). Runs
// after RigIctEyeballs: an eyeball's front pole is +z from its joint's pivot.
void PaintIctParts(const std::vector<int>& face_part, HeadModelData* d) {
  const int parts = static_cast<int>(IctParts().size());
  const int width = parts * kSwatch + kRamp;
  d->texture_height = kTextureRows;
  d->texture_width = width;
  d->texture_mean.assign(static_cast<size_t>(width) * kTextureRows * 3, 0.f);
  auto paint = [&](int x, const Eigen::Vector3f& rgb) {
    for (int y = 0; y < kTextureRows; ++y)
      for (int c = 0; c < 3; ++c) d->texture_mean[(static_cast<size_t>(y) * width + x) * 3 + c] = rgb[c];
  };
  for (int k = 0; k < parts; ++k)
    for (int x = 0; x < kSwatch; ++x) paint(k * kSwatch + x, IctPartAlbedo(IctParts()[k].name));
  for (int j = 0; j < kRamp; ++j) paint(parts * kSwatch + j, IctEyeballAlbedo(M_PI * (j + 0.5) / kRamp));

  // Texture coordinates: one a swatch, then one an eyeball vertex.
  const Eigen::Vector3f left_pivot = d->j_regressor.row(kLeftEyeJoint) * d->v_template,
                        right_pivot = d->j_regressor.row(kRightEyeJoint) * d->v_template;
  std::vector<int> uv_of_vertex(d->v_template.rows(), -1);
  std::vector<std::array<float, 2>> uvs;
  for (int k = 0; k < parts; ++k) uvs.push_back({(k * kSwatch + 0.5f * kSwatch) / width, 0.5f});
  d->uv_faces.resize(d->faces.rows(), 3);
  for (Eigen::Index f = 0; f < d->faces.rows(); ++f)
    for (int c = 0; c < 3; ++c) {
      const int v = d->faces(f, c);
      if (face_part[f] != kEyeballsPart) {
        d->uv_faces(f, c) = face_part[f];
        continue;
      }
      if (uv_of_vertex[v] < 0) {
        const bool left = d->weights(v, kLeftEyeJoint) > 0.5f;
        const Eigen::Vector3f r = d->v_template.row(v).transpose() - (left ? left_pivot : right_pivot);
        const double angle = std::acos(std::clamp(r.z() / std::max(r.norm(), 1e-9f), -1.f, 1.f));
        // Within the ramp's texel centres, so a lookup never reaches the swatches.
        const double texel = std::clamp(angle / M_PI * kRamp - 0.5, 0.0, kRamp - 1.0);
        uv_of_vertex[v] = static_cast<int>(uvs.size());
        uvs.push_back({static_cast<float>((parts * kSwatch + texel + 0.5) / width), 0.5f});
      }
      d->uv_faces(f, c) = uv_of_vertex[v];
    }
  d->uvs.resize(static_cast<Eigen::Index>(uvs.size()), 2);
  for (size_t i = 0; i < uvs.size(); ++i) d->uvs.row(static_cast<Eigen::Index>(i)) << uvs[i][0], uvs[i][1];
}

}  // namespace

Eigen::Vector3f IctPartAlbedo(const std::string& part) {
  // The renders have no shadows: the mouth's lining and tongue are painted
  // about as dark as the inside of an open mouth photographs.
  if (part == "mouth") return {0.20f, 0.07f, 0.07f};
  if (part == "gums_tongue") return {0.36f, 0.13f, 0.13f};
  if (part == "teeth") return {0.80f, 0.76f, 0.68f};
  if (part == "eyes") return {0.72f, 0.50f, 0.46f};  // the sockets' pink lining around the eyeballs
  if (part == "eyeballs") return IctEyeballAlbedo(M_PI / 2);
  return FlatSkinAlbedo();  // skin: the colour every part had unpainted
}

Eigen::Vector3f IctEyeballAlbedo(double angle) {
  // A brown iris about 11.5 mm across on a real eye's 12 mm radius reaches
  // some 26 degrees from the pole, its dark rim included; the pupil a third.
  const double degrees = angle * 180 / M_PI;
  if (degrees < 8) return {0.04f, 0.03f, 0.03f};
  if (degrees < 21) return {0.32f, 0.21f, 0.14f};
  if (degrees < 26) return {0.16f, 0.11f, 0.08f};
  return {0.82f, 0.78f, 0.76f};
}

HeadModel ConvertIctFaceKit(const IctConvertOptions& options) {
  options.Check();
  fs::path dir = options.folder;
  if (!fs::exists(dir / "generic_neutral_mesh.obj") && fs::exists(dir / "FaceXModel" / "generic_neutral_mesh.obj"))
    dir /= "FaceXModel";
  if (!fs::exists(dir / "generic_neutral_mesh.obj"))
    throw std::runtime_error(options.folder + ": not an ICT-FaceKit folder (no generic_neutral_mesh.obj)");
  const fs::path json_path = dir / "vertex_indices.json";
  std::ifstream json_in(json_path);
  if (!json_in) throw std::runtime_error(json_path.string() + ": missing");
  nlohmann::json meta;
  try {
    json_in >> meta;
  } catch (const std::exception& e) {
    throw std::runtime_error(json_path.string() + ": not valid JSON: " + e.what());
  }
  if (!meta.contains("expressions") || !meta["expressions"].is_array())
    throw std::runtime_error(json_path.string() + ": no 'expressions' list");
  const std::vector<std::string> expr_names = meta["expressions"].get<std::vector<std::string>>();

  const ObjMesh neutral = ReadObj(dir / "generic_neutral_mesh.obj", true);
  const int n_all = static_cast<int>(neutral.v.size() / 3);
  const int n_expected = IctParts().back().last + 1;
  if (n_all != n_expected)
    throw std::runtime_error((dir / "generic_neutral_mesh.obj").string() + ": " + std::to_string(n_all) +
                             " vertices, expected " + std::to_string(n_expected) + " (ICT-FaceKit Light topology)");

  // Which vertices to keep, and their new indices.
  std::vector<int> remap(n_all, -1);
  int n = 0;
  for (int i = 0; i < n_all; ++i) {
    bool keep = options.parts.empty();
    for (const auto& name : options.parts)
      for (const auto& part : IctParts())
        if (name == part.name && i >= part.first && i <= part.last) keep = true;
    if (keep) remap[i] = n++;
  }
  for (int id : IctLandmarkVertices())
    if (remap[id] < 0)
      throw std::runtime_error("ICT conversion: the selected parts drop landmark vertex " + std::to_string(id) +
                               "; include 'face'");

  constexpr float kMetresPerCm = 0.01f;
  HeadModelData d;
  d.name = "ICT-FaceKit";
  d.description =
      "ICT-FaceKit Light (MIT licence), converted by headcast: centimetres to metres; expression "
      "components are ARKit-style blendshapes (coefficients 0..1), not orthonormal PCA; the eyeballs are skinned to "
      "the eye joints (gaze), all else to the root.";
  d.v_template.resize(n, 3);
  for (int i = 0; i < n_all; ++i)
    if (remap[i] >= 0)
      for (int c = 0; c < 3; ++c) d.v_template(remap[i], c) = neutral.v[3 * i + c] * kMetresPerCm;

  auto read_basis = [&](const std::vector<std::string>& names, Eigen::MatrixXf* basis) {
    basis->resize(3 * n, static_cast<Eigen::Index>(names.size()));
    for (size_t k = 0; k < names.size(); ++k) {
      const fs::path p = dir / (names[k] + ".obj");
      const ObjMesh m = ReadObj(p, false);
      if (m.v.size() != neutral.v.size())
        throw std::runtime_error(p.string() + ": " + std::to_string(m.v.size() / 3) + " vertices, expected " +
                                 std::to_string(n_all));
      for (int i = 0; i < n_all; ++i)
        if (remap[i] >= 0)
          for (int c = 0; c < 3; ++c)
            (*basis)(3 * remap[i] + c, k) = (m.v[3 * i + c] - neutral.v[3 * i + c]) * kMetresPerCm;
    }
  };
  read_basis(expr_names, &d.expressiondirs);
  d.expression_names = expr_names;
  d.expression_min = 0;  // ARKit coefficients
  d.expression_max = 1;
  std::vector<std::string> id_names;
  for (int k = 0; k < options.max_identity; ++k) {
    char name[32];
    std::snprintf(name, sizeof(name), "identity%03d", k);
    if (!fs::exists(dir / (std::string(name) + ".obj"))) break;
    id_names.push_back(name);
  }
  read_basis(id_names, &d.shapedirs);
  d.shape_names = id_names;

  // Faces: keep those whose three vertices all survive.
  std::vector<std::array<int, 3>> faces, uv_faces;
  std::vector<int> face_part;  // index in IctParts(), by the face's first vertex
  for (size_t f = 0; f < neutral.f.size(); ++f) {
    const auto& t = neutral.f[f];
    if (t[0] < 0 || t[1] < 0 || t[2] < 0 || t[0] >= n_all || t[1] >= n_all || t[2] >= n_all)
      throw std::runtime_error("generic_neutral_mesh.obj: face " + std::to_string(f) +
                               " has a vertex index out of range");
    if (remap[t[0]] < 0 || remap[t[1]] < 0 || remap[t[2]] < 0) continue;
    faces.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
    uv_faces.push_back(neutral.ft[f]);
    int part = 0;
    while (t[0] > IctParts()[part].last) ++part;
    face_part.push_back(part);
  }
  d.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) d.faces.row(f) << faces[f][0], faces[f][1], faces[f][2];
  const int n_uv = static_cast<int>(neutral.vt.size() / 2);
  bool uv_ok = n_uv > 0;
  for (const auto& t : uv_faces)
    for (int k : t) uv_ok &= k >= 0 && k < n_uv;
  if (uv_ok && !options.paint_parts) {
    d.uvs.resize(n_uv, 2);
    for (int i = 0; i < n_uv; ++i) d.uvs.row(i) << neutral.vt[2 * i], 1.f - neutral.vt[2 * i + 1];  // OBJ v is up
    d.uv_faces.resize(d.faces.rows(), 3);
    for (size_t f = 0; f < uv_faces.size(); ++f) d.uv_faces.row(f) << uv_faces[f][0], uv_faces[f][1], uv_faces[f][2];
  }

  // Every vertex on the root (the eyeballs move to the eye joints below);
  // joints at the centroid of the face part (so a root rotation turns the head about its middle).
  d.weights = decltype(d.weights)::Zero(n, kNumHeadJoints);
  d.weights.col(kRootJoint).setOnes();
  d.j_regressor = Eigen::MatrixXf::Zero(kNumHeadJoints, n);
  const IctPart& face = IctParts()[0];
  int face_count = 0;
  for (int i = face.first; i <= face.last; ++i) face_count += remap[i] >= 0;
  for (int i = face.first; i <= face.last; ++i)
    if (remap[i] >= 0) d.j_regressor.col(remap[i]).setConstant(1.0f / face_count);
  RigIctEyeballs(remap, &d);
  if (options.paint_parts) PaintIctParts(face_part, &d);
  d.posedirs.resize(0, 0);

  // Landmarks: the fixed vertex ids, each as a corner of a face that uses it.
  d.lmk_faces = Eigen::VectorXi::Constant(kNumLandmarks, -1);
  d.lmk_bary = RowMatrixX3f::Zero(kNumLandmarks, 3);
  for (int l = 0; l < kNumLandmarks; ++l) {
    const int v = remap[IctLandmarkVertices()[l]];
    for (Eigen::Index f = 0; f < d.faces.rows() && d.lmk_faces[l] < 0; ++f)
      for (int c = 0; c < 3; ++c)
        if (d.faces(f, c) == v) {
          d.lmk_faces[l] = static_cast<int>(f);
          d.lmk_bary(l, c) = 1;
          break;
        }
    if (d.lmk_faces[l] < 0)
      throw std::runtime_error("ICT conversion: landmark vertex " + std::to_string(v) + " is on no face");
  }
  return HeadModel(std::move(d));
}

}  // namespace headcast
