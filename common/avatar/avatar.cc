// Avatar creation, saving and loading.
#include "common/avatar/avatar.h"

#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "common/avatar/avatar_model.h"
#include "common/core/zip_archive.h"
#include "common/raster/shading.h"

namespace headcast {

struct Avatar::Impl {
  explicit Impl(const AvatarConfig& c) : config(c), modules(c) {}
  AvatarConfig config;
  SubjectParams subject;
  std::string fingerprint;
  std::optional<CameraContract> camera_contract;
  nlohmann::json tracking_anchor;  // null: none
  nlohmann::json tracking_fit;     // null: none
  nlohmann::json training_summary = nlohmann::json::object();
  AvatarModules modules;
};

Avatar::Avatar() = default;
Avatar::Avatar(Avatar&&) noexcept = default;
Avatar& Avatar::operator=(Avatar&&) noexcept = default;
Avatar::~Avatar() = default;
const AvatarConfig& Avatar::config() const { return impl_->config; }
const SubjectParams& Avatar::subject() const { return impl_->subject; }
SubjectParams& Avatar::mutable_subject() { return impl_->subject; }
const std::string& Avatar::head_model_fingerprint() const { return impl_->fingerprint; }
const std::optional<CameraContract>& Avatar::camera_contract() const { return impl_->camera_contract; }
void Avatar::set_camera_contract(const CameraContract& contract) { impl_->camera_contract = contract; }
const nlohmann::json& Avatar::tracking_anchor() const { return impl_->tracking_anchor; }
void Avatar::set_tracking_anchor(const nlohmann::json& reference) { impl_->tracking_anchor = reference; }
const nlohmann::json& Avatar::tracking_fit() const { return impl_->tracking_fit; }
void Avatar::set_tracking_fit(const nlohmann::json& settings) { impl_->tracking_fit = settings; }
nlohmann::json& Avatar::training_summary() { return impl_->training_summary; }
const nlohmann::json& Avatar::training_summary() const { return impl_->training_summary; }
AvatarModules& Avatar::modules() { return impl_->modules; }
const AvatarModules& Avatar::modules() const { return impl_->modules; }

SubjectParams DefaultSubject(const HeadModel& model, int output_size) {
  SubjectParams s;
  s.shape = Eigen::VectorXf::Zero(model.num_shape());
  s.texture = Eigen::VectorXf::Zero(model.num_texture());
  s.light = DefaultLighting();
  s.intrinsics = PinholeCamera::FromFovY(output_size, output_size, 24);
  return s;
}

AvatarConfig FitConfigToModel(AvatarConfig config, const HeadModel& model) {
  config.num_shape = std::min(config.num_shape, model.num_shape());
  config.num_expression = std::min(config.num_expression, model.num_expression());
  config.num_texture = std::min(config.num_texture, model.num_texture());
  return config;
}

namespace {

void CheckSubjectMatches(const AvatarConfig& c, const SubjectParams& s, const HeadModel& model) {
  if (c.num_shape > model.num_shape() || c.num_expression > model.num_expression() ||
      c.num_texture > std::max(model.num_texture(), 0))
    throw std::invalid_argument("avatar config uses more shape/expression/texture components than the head model '" +
                                model.data().name + "' has (" + std::to_string(model.num_shape()) + "/" +
                                std::to_string(model.num_expression()) + "/" + std::to_string(model.num_texture()) +
                                ")");
  s.intrinsics.Check();
  if (s.intrinsics.width != c.output_size || s.intrinsics.height != c.output_size)
    throw std::invalid_argument("subject intrinsics are " + std::to_string(s.intrinsics.width) + "x" +
                                std::to_string(s.intrinsics.height) + ", the avatar renders " +
                                std::to_string(c.output_size) + "x" + std::to_string(c.output_size));
  if (!s.shape.allFinite() || !s.texture.allFinite()) throw std::invalid_argument("subject parameters are not finite");
}

std::vector<float> ToVector(const Eigen::VectorXf& v) { return std::vector<float>(v.data(), v.data() + v.size()); }
Eigen::VectorXf FromVector(const std::vector<float>& v) {
  return Eigen::Map<const Eigen::VectorXf>(v.data(), static_cast<Eigen::Index>(v.size()));
}

}  // namespace

Avatar Avatar::CreateRandom(const AvatarConfig& requested, const HeadModel& model, const SubjectParams& subject,
                            uint64_t seed) {
  requested.Check();
  const AvatarConfig config = FitConfigToModel(requested, model);
  CheckSubjectMatches(config, subject, model);
  torch::manual_seed(seed);
  Avatar a;
  a.impl_ = std::make_unique<Impl>(config);
  a.impl_->subject = subject;
  a.impl_->fingerprint = model.fingerprint();
  a.impl_->training_summary = {{"trained", false},
                               {"note", "randomly initialised (seed " + std::to_string(seed) + ")"}};
  return a;
}

Avatar Avatar::WithRuntimeSwitches(const AvatarConfig& config) const {
  config.Check();
  const AvatarConfig& c = impl_->config;
  if (config.feature_channels != c.feature_channels || config.num_shape != c.num_shape ||
      config.num_expression != c.num_expression || config.num_texture != c.num_texture ||
      config.pe_frequencies != c.pe_frequencies || config.pe_scale != c.pe_scale || config.mlp_width != c.mlp_width ||
      config.mlp_layers != c.mlp_layers || config.skip_layer != c.skip_layer ||
      config.renderer_channels != c.renderer_channels)
    throw std::invalid_argument(
        "WithRuntimeSwitches: the network architecture differs; only run-time switches may change");
  const bool adds_surface = !c.has_surface() && config.has_surface();
  if (!adds_surface &&
      (config.surface_features != c.surface_features || config.surface_resolution != c.surface_resolution ||
       config.surface_extent != c.surface_extent || config.surface_conditioned != c.surface_conditioned ||
       config.surface_hidden_channels() != c.surface_hidden_channels() || config.surface_levels != c.surface_levels ||
       config.surface_rigid != c.surface_rigid || config.surface_displacement != c.surface_displacement ||
       config.surface_eye_symmetry != c.surface_eye_symmetry || config.surface_blend != c.surface_blend ||
       config.surface_blend_components != c.surface_blend_components))
    throw std::invalid_argument(
        "WithRuntimeSwitches: the surface texture differs; it can only be added to an avatar without one");
  Avatar a;
  a.impl_ = std::make_unique<Impl>(config);
  a.impl_->subject = impl_->subject;
  // The subject's camera renders the new size (the same field of view), or
  // the avatar would save a file its own Load refuses.
  if (config.output_size != c.output_size)
    a.impl_->subject.intrinsics = impl_->subject.intrinsics.Resized(config.output_size, config.output_size);
  a.impl_->fingerprint = impl_->fingerprint;
  a.impl_->camera_contract = impl_->camera_contract;
  a.impl_->tracking_anchor = impl_->tracking_anchor;
  a.impl_->tracking_fit = impl_->tracking_fit;
  a.impl_->training_summary = impl_->training_summary;
  torch::NoGradGuard no_grad;
  // Every tensor of the source; parts it lacks (an added surface texture and
  // its renderer branch) keep their initial values, which leave the picture unchanged.
  auto copy = [](const torch::nn::Module& from, torch::nn::Module& to) {
    auto src = from.named_parameters();
    for (auto& p : to.named_parameters())
      if (const torch::Tensor* t = src.find(p.key())) p.value().copy_(*t);
    auto bsrc = from.named_buffers();
    for (auto& b : to.named_buffers())
      if (const torch::Tensor* t = bsrc.find(b.key())) b.value().copy_(*t);
  };
  copy(*impl_->modules.cnerf, *a.impl_->modules.cnerf);
  copy(*impl_->modules.renderer, *a.impl_->modules.renderer);
  if (impl_->modules.surface) copy(*impl_->modules.surface, *a.impl_->modules.surface);
  return a;
}

void Avatar::Save(const std::string& path, const cv::Mat& preview) const {
  const Impl& m = *impl_;
  const auto& s = m.subject;
  nlohmann::json manifest = {{"format", "headcast-avatar"},
                             {"format_version", kAvatarFormatVersion},
                             {"kind", "cnerf"},
                             {"config", m.config.ToJson()},
                             {"output_resolution", m.config.output_size},
                             {"head_model", {{"fingerprint", m.fingerprint}}},
                             {"training_summary", m.training_summary},
                             {"subject",
                              {{"shape", ToVector(s.shape)},
                               {"texture", ToVector(s.texture)},
                               {"light", std::vector<float>(s.light.begin(), s.light.end())},
                               {"intrinsics", CameraToJson(s.intrinsics)}}}};
  if (m.camera_contract) manifest["camera"] = m.camera_contract->ToJson();
  if (!m.tracking_anchor.is_null()) manifest["tracking_anchor"] = m.tracking_anchor;
  if (!m.tracking_fit.is_null()) manifest["tracking_fit"] = m.tracking_fit;
  torch::serialize::OutputArchive root, cnerf, renderer, surface;
  m.modules.cnerf->save(cnerf);
  m.modules.renderer->save(renderer);
  root.write("cnerf", cnerf);
  root.write("renderer", renderer);
  if (m.modules.surface) {
    m.modules.surface->save(surface);
    root.write("surface", surface);
  }
  std::ostringstream weights;
  root.save_to(weights);
  ZipEntries entries = {{"manifest.json", manifest.dump(2)}, {"weights.pt", weights.str()}};
  if (!preview.empty()) {
    std::vector<uchar> png;
    cv::imencode(".png", preview, png);
    entries["preview.png"] = std::string(png.begin(), png.end());
  }
  WriteZip(path, entries, /*compress=*/false);  // weights do not compress; saving stays fast
}

nlohmann::json Avatar::ReadManifest(const std::string& path) {
  const ZipEntries entries = ReadZip(path, "manifest.json");  // not the weights
  auto it = entries.find("manifest.json");
  if (it == entries.end()) throw std::runtime_error(path + ": not a headcast avatar (no manifest.json)");
  nlohmann::json manifest;
  try {
    manifest = nlohmann::json::parse(it->second);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": manifest.json is not valid JSON: " + e.what());
  }
  if (manifest.value("format", "") != "headcast-avatar")
    throw std::runtime_error(path + ": not a headcast avatar file");
  return manifest;
}

Avatar Avatar::Load(const std::string& path, const HeadModel& model) {
  const ZipEntries entries = ReadZip(path);
  const nlohmann::json manifest = ReadManifest(path);
  const int version = manifest.value("format_version", -1);
  if (version != kAvatarFormatVersion)
    throw std::runtime_error(path + ": avatar format version " + std::to_string(version) +
                             ", this build reads version " + std::to_string(kAvatarFormatVersion) +
                             (version > kAvatarFormatVersion ? " (update headcast)" : " (re-export the avatar)"));
  if (const std::string kind = manifest.value("kind", std::string("cnerf")); kind != "cnerf")
    throw std::runtime_error(path + ": a '" + kind + "' avatar, not a CNeRF one (open it with OpenAvatarBackend)");
  const std::string fingerprint = manifest.value("/head_model/fingerprint"_json_pointer, std::string());
  if (fingerprint != model.fingerprint())
    throw std::runtime_error(path + ": made for head model " + fingerprint + ", but the loaded head model '" +
                             model.data().name + "' is " + model.fingerprint() +
                             "; load the head model the avatar was trained with");
  Avatar a;
  try {
    const AvatarConfig config = AvatarConfig::FromJson(manifest.at("config"));
    a.impl_ = std::make_unique<Impl>(config);
    const auto& subj = manifest.at("subject");
    SubjectParams& s = a.impl_->subject;
    s.shape = FromVector(subj.at("shape").get<std::vector<float>>());
    s.texture = FromVector(subj.at("texture").get<std::vector<float>>());
    const auto light = subj.at("light").get<std::vector<float>>();
    if (light.size() != 27) throw std::invalid_argument("light needs 27 values");
    std::copy(light.begin(), light.end(), s.light.begin());
    s.intrinsics = CameraFromJson(subj.at("intrinsics"));
    CheckSubjectMatches(config, s, model);
    a.impl_->fingerprint = fingerprint;
    if (manifest.contains("camera")) a.impl_->camera_contract = CameraContract::FromJson(manifest.at("camera"));
    a.impl_->tracking_anchor = manifest.value("tracking_anchor", nlohmann::json());
    a.impl_->tracking_fit = manifest.value("tracking_fit", nlohmann::json());
    a.impl_->training_summary = manifest.value("training_summary", nlohmann::json::object());
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": bad manifest: " + e.what());
  }
  auto w = entries.find("weights.pt");
  if (w == entries.end()) throw std::runtime_error(path + ": no weights.pt in the avatar");
  try {
    std::istringstream in(w->second);
    torch::serialize::InputArchive root, cnerf, renderer, surface;
    root.load_from(in);
    root.read("cnerf", cnerf);
    root.read("renderer", renderer);
    if (a.impl_->modules.surface) root.read("surface", surface);
    // libtorch's load replaces tensors whole (shape included), so a file whose
    // weights disagree with its config would load "fine": compare shapes.
    auto load_checked = [&](torch::nn::Module& module, torch::serialize::InputArchive& archive,
                            const std::string& name) {
      std::map<std::string, std::vector<int64_t>> expected;
      for (const auto& p : module.named_parameters()) expected[p.key()] = p.value().sizes().vec();
      for (const auto& b : module.named_buffers()) expected[b.key()] = b.value().sizes().vec();
      module.load(archive);
      auto check = [&](const std::string& key, const torch::Tensor& t) {
        if (t.sizes().vec() != expected[key])
          throw std::runtime_error(name + "." + key + " has shape " + c10::str(t.sizes()) + ", the config needs " +
                                   c10::str(c10::IntArrayRef(expected[key])));
      };
      for (const auto& p : module.named_parameters()) check(p.key(), p.value());
      for (const auto& b : module.named_buffers()) check(b.key(), b.value());
    };
    load_checked(*a.impl_->modules.cnerf, cnerf, "cnerf");
    load_checked(*a.impl_->modules.renderer, renderer, "renderer");
    if (a.impl_->modules.surface) load_checked(*a.impl_->modules.surface, surface, "surface");
  } catch (const c10::Error& e) {
    throw std::runtime_error(
        path + ": weights do not match the avatar's config or are corrupt: " + e.what_without_backtrace());
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": weights do not match the avatar's config or are corrupt: " + e.what());
  }
  return a;
}

}  // namespace headcast
