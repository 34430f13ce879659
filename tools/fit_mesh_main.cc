// headcast-fit-mesh: head-model parameters for a given polygonal head
// (METHOD §8). Prints a JSON summary on stdout and writes PARAMS.json, which
// `headcast-track --identity-from` (and training) take the identity from.
#include <CLI/CLI.hpp>
#include <cmath>
#include <fstream>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "common/core/log.h"
#include "common/core/npy.h"
#include "common/core/program.h"
#include "common/core/rotation.h"
#include "common/core/timer.h"
#include "common/core/version.h"
#include "common/headmodel/head_model_io.h"
#include "common/tracking/mesh_fitter.h"

namespace {
using namespace headcast;

// Landmarks on the mesh: JSON {"36": [x, y, z], ...} or text lines "index x y z".
std::vector<std::pair<int, Eigen::Vector3d>> ReadLandmarks(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::stringstream text;
  text << in.rdbuf();
  std::vector<std::pair<int, Eigen::Vector3d>> out;
  const std::string s = text.str();
  const auto first = s.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && s[first] == '{') {
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(s);
    } catch (const std::exception& e) {
      throw std::runtime_error(path + ": not JSON (" + e.what() + ")");
    }
    if (!j.is_object()) throw std::runtime_error(path + ": wants {\"index\": [x, y, z], ...}");
    for (auto it = j.begin(); it != j.end(); ++it) {
      const auto& p = it.value();
      if (!p.is_array() || p.size() != 3 || !p[0].is_number() || !p[1].is_number() || !p[2].is_number())
        throw std::runtime_error(path + ": landmark " + it.key() + " is not [x, y, z]");
      out.emplace_back(ParseNumber<int>(it.key(), path + ": landmark index"),
                       Eigen::Vector3d(p[0].get<double>(), p[1].get<double>(), p[2].get<double>()));
    }
  } else {
    std::istringstream ls(s);
    int index;
    double x, y, z;
    while (ls >> index >> x >> y >> z) out.emplace_back(index, Eigen::Vector3d(x, y, z));
    if (!ls.eof()) throw std::runtime_error(path + ": expected lines of 'index x y z'");
  }
  return out;
}

// Importance map: .npy of N floats, or text with one value per line.
Eigen::VectorXf ReadImportance(const std::string& path) {
  if (path.size() > 4 && path.substr(path.size() - 4) == ".npy") {
    const std::vector<float> v = ReadNpy(path).ToFloats();
    return Eigen::Map<const Eigen::VectorXf>(v.data(), static_cast<Eigen::Index>(v.size()));
  }
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::vector<float> v;
  for (float x; in >> x;) v.push_back(x);
  if (!in.eof()) throw std::runtime_error(path + ": expected one number per vertex");
  return Eigen::Map<const Eigen::VectorXf>(v.data(), static_cast<Eigen::Index>(v.size()));
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"headcast-fit-mesh: fit the head model to a polygonal head mesh (weighted residual, METHOD §8)"};
  headcast::AddVersionFlag(app);
  headcast::AddConfigFile(app);
  app.fallthrough();  // global flags (--log, --config) after a subcommand too
  std::string mesh_path, head_model_spec = "builtin", out, fit = "shape,expression,pose", unit = "m", topology = "auto",
                         weights = "importance-count", loss = "norm", importance, landmarks, fitted_mesh, log_level;
  bool black_box = false;
  MeshFitOptions o;
  app.add_option("--mesh", mesh_path, "the head mesh (.obj or .ply)")->required();
  app.add_option("--head-model", head_model_spec, "builtin or a head-model .npz")->capture_default_str();
  app.add_option("--out", out, "PARAMS.json to write")->required();
  app.add_option("--fit", fit, "what to fit: any of shape, expression, pose (jaw); the rigid alignment always")
      ->capture_default_str();
  app.add_flag("--scale", o.fit_scale, "fit a uniform scale too (a similarity)");
  app.add_option("--unit", unit, "unit of the mesh's coordinates: m, cm or mm")->capture_default_str();
  app.add_option("--topology", topology,
                 "auto, same (vertex i is model vertex i) or other (closest points; needs --landmarks or --prealigned)")
      ->capture_default_str();
  app.add_option("--weights", weights, "importance-count (nu*phi), importance (nu) or uniform")->capture_default_str();
  app.add_option("--importance", importance, "per-vertex importance nu overriding the default (.npy or text)");
  app.add_option("--loss", loss, "norm (the paper's sum of distances), squared or cauchy")->capture_default_str();
  app.add_option("--loss-scale", o.loss_scale_m, "metres where the loss turns linear / saturates")
      ->capture_default_str();
  app.add_option("--num-shape", o.num_shape, "shape components fitted (0: all)")->capture_default_str();
  app.add_option("--num-expression", o.num_expression, "expression components fitted (0: all)")->capture_default_str();
  app.add_option("--landmarks", landmarks,
                 "landmarks on the mesh for the rigid pre-alignment (other topology): JSON {\"36\": [x,y,z], ...} or "
                 "lines 'index x y z', indices of the 68-point scheme; at least 4 (eye corners 36 45, nose 30, "
                 "mouth corners 48 54 work well)");
  app.add_flag("--prealigned", o.prealigned, "the mesh is already in the head model's frame (no landmarks needed)");
  app.add_option("--max-distance", o.max_correspondence_m, "closest-point pairs farther apart are ignored, metres")
      ->capture_default_str();
  app.add_option("--rounds", o.closest_point_rounds, "closest-point rounds at most")->capture_default_str();
  app.add_flag("--allow-non-manifold", o.allow_non_manifold, "accept meshes with edges shared by 3+ faces");
  app.add_flag("--black-box", black_box,
               "treat the head model as a black box (numeric derivatives, same topology only): the paper's setting");
  app.add_option("--fitted-mesh", fitted_mesh, "also write the fitted model mesh (.obj/.ply) in the mesh's frame");
  app.add_option("--log", log_level, "log level");
  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging(log_level);
    const HeadModel model = LoadHeadModelSpec(head_model_spec);
    TriangleMesh mesh = ReadMesh(mesh_path);
    const std::map<std::string, double> units = {{"m", 1.0}, {"cm", 0.01}, {"mm", 0.001}};
    if (!units.count(unit)) throw std::invalid_argument("--unit must be m, cm or mm");
    mesh.vertices *= static_cast<float>(units.at(unit));
    o.fit_shape = fit.find("shape") != std::string::npos;
    o.fit_expression = fit.find("expression") != std::string::npos;
    o.fit_jaw = fit.find("pose") != std::string::npos;
    std::stringstream items(fit);
    for (std::string item; std::getline(items, item, ',');)
      if (item != "shape" && item != "expression" && item != "pose")
        throw std::invalid_argument("--fit: unknown item '" + item + "' (shape, expression, pose)");
    const std::map<std::string, MeshCorrespondence> topologies = {{"auto", MeshCorrespondence::kAuto},
                                                                  {"same", MeshCorrespondence::kSameTopology},
                                                                  {"other", MeshCorrespondence::kClosestPoint}};
    const std::map<std::string, MeshWeighting> weightings = {{"importance-count", MeshWeighting::kImportanceAndCount},
                                                             {"importance", MeshWeighting::kImportance},
                                                             {"uniform", MeshWeighting::kUniform}};
    const std::map<std::string, MeshLoss> losses = {
        {"norm", MeshLoss::kNorm}, {"squared", MeshLoss::kSquared}, {"cauchy", MeshLoss::kCauchy}};
    if (!topologies.count(topology)) throw std::invalid_argument("--topology must be auto, same or other");
    if (!weightings.count(weights))
      throw std::invalid_argument("--weights must be importance-count, importance or uniform");
    if (!losses.count(loss)) throw std::invalid_argument("--loss must be norm, squared or cauchy");
    o.correspondence = topologies.at(topology);
    o.weighting = weightings.at(weights);
    o.loss = losses.at(loss);
    if (!importance.empty()) o.importance = ReadImportance(importance);
    if (!landmarks.empty()) {
      o.target_landmarks = ReadLandmarks(landmarks);
      for (auto& [index, point] : o.target_landmarks) point *= units.at(unit);
    }
    Stopwatch clock;
    MeshFitResult result;
    nlohmann::json extra = {{"mesh", mesh_path}, {"weights", weights}, {"loss", loss}};
    if (black_box) {
      // The paper's setting: the fitter sees only a function from K numbers to
      // vertices (shape, expression, jaw, rotation, translation).
      o.correspondence = MeshCorrespondence::kSameTopology;
      CheckMeshForFit(model, mesh, o);
      const int ns = o.ShapeCount(model), ne = o.ExpressionCount(model);
      const int nj = o.fit_jaw && model.JointIsArticulated(kJawJoint) ? 3 : 0;
      auto unpack = [&](const Eigen::VectorXd& x, MeshFitResult* r) {
        r->params.shape = Eigen::VectorXd::Zero(model.num_shape());
        r->params.expression = Eigen::VectorXd::Zero(model.num_expression());
        r->params.shape.head(ns) = x.head(ns);
        r->params.expression.head(ne) = x.segment(ns, ne);
        r->params.pose.setZero();
        if (nj) r->params.pose.segment<3>(3 * kJawJoint) = x.segment<3>(ns + ne);
        r->rotation = AxisAngleToMatrix(x.segment<3>(ns + ne + nj));
        r->translation = x.segment<3>(ns + ne + nj + 3);
        r->scale = 1;
      };
      const MeshGenerator generator = [&](const Eigen::VectorXd& x, RowMatrixX3f* v) {
        MeshFitResult r;
        unpack(x, &r);
        *v = FittedVertices(model, r);
      };
      // Start from a rigid-only analytic pre-alignment.
      MeshFitOptions rigid = o;
      rigid.fit_shape = rigid.fit_expression = rigid.fit_jaw = false;
      const MeshFitResult start = FitHeadModelToMesh(model, mesh, rigid);
      Eigen::VectorXd x = Eigen::VectorXd::Zero(ns + ne + nj + 6);
      x.segment<3>(ns + ne + nj) = MatrixToAxisAngle(start.rotation);
      x.tail<3>() = start.translation;
      const BlackBoxFitResult bb = FitBlackBoxToMesh(generator, x, mesh.vertices, MeshFitWeights(model, o));
      unpack(bb.params, &result);
      result.rms_m = bb.rms_m;
      result.correspondences = model.num_vertices();
      extra["black_box_generator_calls"] = bb.generator_calls;
    } else {
      result = FitHeadModelToMesh(model, mesh, o);
    }
    extra["seconds"] = clock.ElapsedSeconds();
    WriteMeshFitJson(out, model, result, extra.dump());
    if (!fitted_mesh.empty()) WriteMesh(fitted_mesh, TriangleMesh{FittedVertices(model, result), model.data().faces});
    nlohmann::json summary = {{"out", out},
                              {"same_topology", result.same_topology},
                              {"rms_mm", 1e3 * result.rms_m},
                              {"rms_face_mm", 1e3 * result.rms_face_m},
                              {"correspondences", result.correspondences},
                              {"rounds", result.rounds},
                              {"seconds", clock.ElapsedSeconds()}};
    std::cout << summary.dump(2) << "\n";
  } catch (const std::exception& e) {
    spdlog::error("{}", headcast::InFlagNames(app, e.what()));
    return 1;
  }
  return 0;
}
