// AvatarConfig checks and JSON.
#include "common/avatar/avatar_config.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/core/options.h"

namespace headcast {

void AvatarCommonConfig::CheckCommon(OptionsCheck* c) const {
  c->That(output_size == 128 || output_size == 256 || output_size == 512,
          "output_size must be 128, 256 or 512 (got " + std::to_string(output_size) + ")");
  c->InRange("num_shape", num_shape, 0, 400).InRange("num_expression", num_expression, 0, 400);
  c->InRange("num_texture", num_texture, 0, 400);
}

const char* MatteModeName(MatteMode mode) {
  switch (mode) {
    case MatteMode::kNone:
      return "none";
    case MatteMode::kLearned:
      return "learned";
    case MatteMode::kBounded:
      return "bounded";
  }
  return "?";
}

MatteMode ParseMatteMode(const std::string& name) {
  for (MatteMode m : {MatteMode::kNone, MatteMode::kLearned, MatteMode::kBounded})
    if (name == MatteModeName(m)) return m;
  throw std::invalid_argument("unknown matte '" + name + "' (none, learned or bounded)");
}

const char* MotionConditioningName(MotionConditioning mode) {
  switch (mode) {
    case MotionConditioning::kFull:
      return "full";
    case MotionConditioning::kNoExpression:
      return "no_expression";
    case MotionConditioning::kNeck:
      return "neck";
  }
  return "?";
}

MotionConditioning ParseMotionConditioning(const std::string& name) {
  for (MotionConditioning m : {MotionConditioning::kFull, MotionConditioning::kNoExpression, MotionConditioning::kNeck})
    if (name == MotionConditioningName(m)) return m;
  throw std::invalid_argument("unknown motion conditioning '" + name + "' (full, no_expression or neck)");
}

bool AvatarConfig::Tells(MotionConditioning mode, int i) const {
  if (i < pose_offset()) return true;
  if (i >= expression_offset()) return mode == MotionConditioning::kFull;
  return mode != MotionConditioning::kNeck || i < pose_offset() + 3;  // the neck is the first joint
}

void AvatarConfig::Check() const {
  OptionsCheck c("AvatarConfig");
  CheckCommon(&c);
  c.InRange("feature_channels", feature_channels, 3, 1024);
  c.InRange("pe_frequencies", pe_frequencies, 0, 16);
  c.Positive("pe_scale", pe_scale).InRange("mlp_width", mlp_width, 8, 2048).InRange("mlp_layers", mlp_layers, 1, 16);
  c.That(skip_layer == -1 || (skip_layer >= 1 && skip_layer < mlp_layers),
         "skip_layer must be -1 or in [1, mlp_layers)");
  c.InRange("samples_per_ray", samples_per_ray, 1, 512);
  c.NonNegative("shell_front", shell_front).NonNegative("shell_back", shell_back);
  c.That(shell_front + shell_back > 0, "shell_front + shell_back must be > 0");
  c.InRange("hair_margin_px", hair_margin_px, 0, 64);
  c.Positive("uniform_near", uniform_near).Positive("uniform_far", uniform_far);
  c.That(renderer_channels.size() == 3 || renderer_channels.size() == 4,
         "renderer_channels needs 3 or 4 entries (into each x2 level and out of the last: 2 or 3 levels)");
  for (int ch : renderer_channels) c.InRange("renderer_channels[i]", ch, 1, 1024);
  c.That(renderer_channels.empty() || renderer_channels[0] == feature_channels,
         "renderer_channels[0] must equal feature_channels");
  c.InRange("surface_features", surface_features, 0, 64).InRange("surface_resolution", surface_resolution, 8, 2048);
  c.InRange("surface_extent", surface_extent, 0.01, 2.0);
  c.InRange("surface_shell", surface_shell, 0.0, 0.2);
  c.That(surface_shell == 0 || has_surface(), "surface_shell needs surface_features > 0");
  c.That(!surface_rigid || has_surface(), "surface_rigid needs surface_features > 0");
  c.That(!surface_rigid || surface_shell == 0,
         "surface_rigid takes no surface_shell (a shell pixel has no posed point)");
  c.That(!surface_displacement || has_surface(), "surface_displacement needs surface_features > 0");
  c.That(!surface_displacement || surface_shell == 0,
         "surface_displacement takes no surface_shell (a shell pixel has no posed point)");
  c.That(!surface_eye_symmetry || has_surface(), "surface_eye_symmetry needs surface_features > 0");
  c.That(!surface_eye_symmetry || !surface_displacement,
         "surface_eye_symmetry moves the eyeballs' canonical points, which surface_displacement measures from");
  c.That(!surface_conditioned || has_surface(), "surface_conditioned needs surface_features > 0");
  c.That(surface_blend == 0 || (surface_blend >= 4 && surface_blend <= 256), "surface_blend must be 0 or in [4, 256]");
  c.That(surface_blend == 0 || has_surface(), "surface_blend needs surface_features > 0");
  c.That(surface_blend == 0 || num_expression > 0, "surface_blend needs expression coefficients");
  c.That(surface_blend_components >= 0 && surface_blend_components <= num_expression,
         "surface_blend_components must be in [0, num_expression]");
  c.That(surface_blend_components == 0 || surface_blend > 0, "surface_blend_components needs surface_blend");
  c.InRange("surface_hidden", surface_hidden, 0, 256)
      .InRange("surface_levels", surface_levels, 1, std::max(1, renderer_levels()));
  c.That(surface_levels == 1 || has_surface(), "surface_levels needs surface_features > 0");
  c.That(!canonical_samples || sampling == SamplingMode::kMeshGuided,
         "canonical_samples needs mesh-guided sampling (a triangle under every ray)");
  c.That(!rigid_margin || canonical_samples, "rigid_margin needs canonical_samples");
  c.That(!covered_apart || canonical_samples, "covered_apart needs canonical_samples");
  c.InRange("hair_reach", hair_reach, 0.0, 0.05);
  c.That(!has_hair_conditioning() || sampling == SamplingMode::kMeshGuided,
         "hair_conditioning needs mesh-guided sampling (the triangle under each ray tells the hair)");
  c.That(!covered_apart || !surface_displacement,
         "covered_apart moves the covered parts' canonical points, which surface_displacement measures from");
  c.InRange("matte_core", matte_core, 0.0, 0.1).InRange("matte_scale", matte_scale, 0.05, 4.0);
  c.InRange("motion_blur", motion_blur, 0.0, kMaxMotionBlur);
  c.InRange("outline_ramp", outline_ramp, 0.0, 0.5).InRange("outline_centre_y", outline_centre_y, -0.2, 0.2);
  c.InRange("outline_matte_scale", outline_matte_scale, 0.05, 4.0);
  c.That(expression_low.size() == expression_high.size(),
         "expression_low and expression_high must have as many values");
  c.That(expression_low.empty() || static_cast<int>(expression_low.size()) == num_expression,
         "expression span has " + std::to_string(expression_low.size()) + " values, the avatar " +
             std::to_string(num_expression) + " expression coefficients");
  for (size_t i = 0; i < std::min(expression_low.size(), expression_high.size()); ++i)
    c.That(std::isfinite(expression_low[i]) && std::isfinite(expression_high[i]) &&
               expression_low[i] <= expression_high[i],
           "expression span " + std::to_string(i) + " must be finite with low <= high");
  c.That(bias_geometry.empty() == bias_appearance.empty(), "bias_geometry and bias_appearance come together");
  c.That(bias_geometry.empty() || static_cast<int>(bias_geometry.size()) == conditioning_dim(),
         "conditioning bias has " + std::to_string(bias_geometry.size()) + " geometry values, the avatar " +
             std::to_string(conditioning_dim()));
  c.That(bias_appearance.empty() || static_cast<int>(bias_appearance.size()) == appearance_dim(),
         "conditioning bias has " + std::to_string(bias_appearance.size()) + " appearance values, the avatar " +
             std::to_string(appearance_dim()));
  for (const std::vector<float>* bias : {&bias_geometry, &bias_appearance})
    for (float v : *bias)
      c.That(std::isfinite(v) && std::abs(v) <= 10, "conditioning bias values must be finite, |v| <= 10");
  c.ThrowIfErrors();
  matte_rules.Check();
}

float AvatarConfig::ToldExpression(int i, float value) const {
  return has_expression_span() ? std::clamp(value, expression_low[i], expression_high[i]) : value;
}

nlohmann::json AvatarConfig::ToJson() const {
  nlohmann::json j = {{"output_size", output_size},
                      {"feature_channels", feature_channels},
                      {"num_shape", num_shape},
                      {"num_expression", num_expression},
                      {"num_texture", num_texture},
                      {"pe_frequencies", pe_frequencies},
                      {"pe_scale", pe_scale},
                      {"mlp_width", mlp_width},
                      {"mlp_layers", mlp_layers},
                      {"skip_layer", skip_layer},
                      {"sampling", sampling == SamplingMode::kMeshGuided ? "mesh_guided" : "uniform"},
                      {"samples_per_ray", samples_per_ray},
                      {"shell_front", shell_front},
                      {"shell_back", shell_back},
                      {"hair_margin_px", hair_margin_px},
                      {"uniform_near", uniform_near},
                      {"uniform_far", uniform_far},
                      {"precompute_conditioning", precompute_conditioning},
                      {"renderer_channels", renderer_channels},
                      {"canonical_samples", canonical_samples},
                      {"rigid_margin", rigid_margin},
                      {"covered_apart", covered_apart},
                      {"surface_features", surface_features},
                      {"surface_resolution", surface_resolution},
                      {"surface_extent", surface_extent},
                      {"surface_shell", surface_shell},
                      {"surface_rigid", surface_rigid},
                      {"surface_displacement", surface_displacement},
                      {"surface_eye_symmetry", surface_eye_symmetry},
                      {"surface_blend", surface_blend},
                      {"surface_blend_components", surface_blend_components},
                      {"surface_conditioned", surface_conditioned},
                      {"surface_hidden", surface_hidden},
                      {"surface_levels", surface_levels},
                      {"matte", MatteModeName(matte)},
                      {"matte_rules", matte_rules.ToJson()},
                      {"matte_core", matte_core},
                      {"matte_scale", matte_scale},
                      {"motion_blur", motion_blur},
                      {"outline_ramp", outline_ramp},
                      {"outline_centre_y", outline_centre_y},
                      {"outline_matte_scale", outline_matte_scale},
                      {"motion_conditioning", MotionConditioningName(motion_conditioning)},
                      {"hair_conditioning", MotionConditioningName(hair_conditioning)},
                      {"hair_reach", hair_reach},
                      {"view_rotation", view_rotation}};
  if (has_expression_span()) j["expression_span"] = {{"low", expression_low}, {"high", expression_high}};
  if (has_conditioning_bias()) j["conditioning_bias"] = {{"geometry", bias_geometry}, {"appearance", bias_appearance}};
  return j;
}

AvatarConfig AvatarConfig::FromJson(const nlohmann::json& j) {
  AvatarConfig c;
  try {
    c.output_size = j.at("output_size");
    c.feature_channels = j.at("feature_channels");
    c.num_shape = j.at("num_shape");
    c.num_expression = j.at("num_expression");
    c.num_texture = j.at("num_texture");
    c.pe_frequencies = j.at("pe_frequencies");
    c.pe_scale = j.at("pe_scale");
    c.mlp_width = j.at("mlp_width");
    c.mlp_layers = j.at("mlp_layers");
    c.skip_layer = j.at("skip_layer");
    const std::string sampling = j.at("sampling");
    if (sampling != "mesh_guided" && sampling != "uniform")
      throw std::invalid_argument("unknown sampling '" + sampling + "'");
    c.sampling = sampling == "uniform" ? SamplingMode::kUniform : SamplingMode::kMeshGuided;
    c.samples_per_ray = j.at("samples_per_ray");
    c.shell_front = j.at("shell_front");
    c.shell_back = j.at("shell_back");
    c.hair_margin_px = j.at("hair_margin_px");
    c.uniform_near = j.at("uniform_near");
    c.uniform_far = j.at("uniform_far");
    c.precompute_conditioning = j.at("precompute_conditioning");
    c.renderer_channels = j.at("renderer_channels").get<std::vector<int>>();
    // Files from before surface features have none.
    c.canonical_samples = j.value("canonical_samples", false);
    c.rigid_margin = j.value("rigid_margin", false);
    c.covered_apart = j.value("covered_apart", false);
    c.surface_features = j.value("surface_features", 0);
    c.surface_resolution = j.value("surface_resolution", c.surface_resolution);
    c.surface_extent = j.value("surface_extent", c.surface_extent);
    c.surface_shell = j.value("surface_shell", 0.0);  // files from before the shell: the mesh only
    c.surface_rigid = j.value("surface_rigid", false);
    c.surface_displacement = j.value("surface_displacement", false);
    c.surface_eye_symmetry = j.value("surface_eye_symmetry", false);
    c.surface_blend = j.value("surface_blend", 0);
    c.surface_blend_components = j.value("surface_blend_components", 0);
    c.surface_conditioned = j.value("surface_conditioned", false);
    c.surface_hidden = j.value("surface_hidden", 0);
    c.surface_levels = j.value("surface_levels", 1);
    c.matte = ParseMatteMode(j.value("matte", std::string("none")));
    if (j.contains("matte_rules")) c.matte_rules = MatteRules::FromJson(j.at("matte_rules"));
    c.matte_core = j.value("matte_core", 0.0);
    c.matte_scale = j.value("matte_scale", 1.0);
    c.motion_blur = j.value("motion_blur", 0.0);
    c.outline_ramp = j.value("outline_ramp", c.outline_ramp);  // files from before it: only frames with an outline move
    c.outline_centre_y = j.value("outline_centre_y", c.outline_centre_y);
    c.outline_matte_scale = j.value("outline_matte_scale", c.outline_matte_scale);
    c.motion_conditioning = ParseMotionConditioning(j.value("motion_conditioning", std::string("full")));
    c.hair_conditioning = ParseMotionConditioning(j.value("hair_conditioning", std::string("full")));
    c.hair_reach = j.value("hair_reach", c.hair_reach);
    c.view_rotation = j.value("view_rotation", false);
    if (j.contains("expression_span")) {
      c.expression_low = j.at("expression_span").at("low").get<std::vector<float>>();
      c.expression_high = j.at("expression_span").at("high").get<std::vector<float>>();
    }
    if (j.contains("conditioning_bias")) {
      c.bias_geometry = j.at("conditioning_bias").at("geometry").get<std::vector<float>>();
      c.bias_appearance = j.at("conditioning_bias").at("appearance").get<std::vector<float>>();
    }
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("AvatarConfig: bad or missing field: ") + e.what());
  }
  c.Check();
  return c;
}

AvatarConfig AvatarConfig::Default(int output_size) {
  AvatarConfig c;
  c.output_size = output_size;
  if (output_size == 512) c.renderer_channels = {48, 24, 12, 8};
  return c;
}

AvatarConfig AvatarConfig::HeadNeRFSized() {
  AvatarConfig c;
  c.output_size = 256;
  c.feature_channels = 256;
  c.mlp_width = 384;
  c.mlp_layers = 8;
  c.skip_layer = 4;
  c.pe_frequencies = 10;
  c.sampling = SamplingMode::kUniform;
  c.samples_per_ray = 64;
  c.precompute_conditioning = false;
  c.renderer_channels = {256, 128, 64, 32};
  return c;
}

void ApplySubjectDefaults(AvatarConfig* config) {
  config->surface_features = kSubjectSurfaceFeatures;
  config->surface_blend = kSubjectSurfaceBlend;
  config->surface_conditioned = true;
  config->canonical_samples = true;
  config->covered_apart = true;
  config->matte = kSubjectMatte;
}

void ApplyTwoLevelRenderer(AvatarConfig* config) {
  config->renderer_channels = {config->feature_channels, 24, 8};
  config->samples_per_ray = 4;
  config->hair_margin_px = 4;
}

}  // namespace headcast
