#include "common/tracking/anchor_reference.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "common/core/options.h"

namespace headcast {

void PhotometricAnchorOptions::Check() const {
  OptionsCheck c("PhotometricAnchorOptions");
  c.NonNegative("weight", weight).InRange("points", points, 16, 100000).InRange("fit_points", fit_points, 4, 10000);
  c.InRange("rounds", rounds, 1, 10).InRange("blur_iod", blur_iod, 0.0, 0.5).Positive("huber", huber);
  c.InRange("max_shift_iod", max_shift_iod, 0.0, 1.0);
  c.ThrowIfErrors();
}

nlohmann::json PhotometricAnchorOptions::ToJson() const {
  return {{"weight", weight},     {"points", points}, {"fit_points", fit_points},      {"rounds", rounds},
          {"blur_iod", blur_iod}, {"huber", huber},   {"max_shift_iod", max_shift_iod}};
}

PhotometricAnchorOptions PhotometricAnchorOptions::FromJson(const nlohmann::json& j) {
  PhotometricAnchorOptions o;
  try {
    o.weight = j.at("weight").get<double>();
    o.points = j.at("points").get<int>();
    o.fit_points = j.at("fit_points").get<int>();
    o.rounds = j.at("rounds").get<int>();
    o.blur_iod = j.at("blur_iod").get<double>();
    o.huber = j.at("huber").get<double>();
    o.max_shift_iod = j.at("max_shift_iod").get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("photometric anchor options: ") + e.what());
  }
  o.Check();
  return o;
}

int AnchorReference::referenced() const {
  return static_cast<int>(std::count_if(grey.begin(), grey.end(), [](double g) { return !std::isnan(g); }));
}

nlohmann::json AnchorReference::ToJson() const {
  nlohmann::json values = nlohmann::json::array();
  for (double g : grey) values.push_back(std::isnan(g) ? nlohmann::json(nullptr) : nlohmann::json(g));
  return {{"options", options.ToJson()}, {"grey", values}};
}

AnchorReference AnchorReference::FromJson(const nlohmann::json& j) {
  AnchorReference r;
  if (!j.is_object() || !j.contains("options") || !j.contains("grey") || !j.at("grey").is_array())
    throw std::invalid_argument("photometric anchor reference: wants an object with 'options' and a 'grey' array");
  r.options = PhotometricAnchorOptions::FromJson(j.at("options"));
  const nlohmann::json& grey = j.at("grey");
  if (grey.size() != static_cast<size_t>(r.options.points))
    throw std::invalid_argument("photometric anchor reference: " + std::to_string(grey.size()) + " grey levels for " +
                                std::to_string(r.options.points) + " points");
  r.grey.reserve(grey.size());
  for (const nlohmann::json& g : grey) {
    if (g.is_null()) {
      r.grey.push_back(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    if (!g.is_number() || !(g.get<double>() >= 0 && g.get<double>() <= 1))
      throw std::invalid_argument("photometric anchor reference: a grey level that is not a number in 0..1: " +
                                  g.dump());
    r.grey.push_back(g.get<double>());
  }
  if (r.referenced() < kMinAlignPoints)
    throw std::invalid_argument("photometric anchor reference: " + std::to_string(r.referenced()) +
                                " points with a reference, an alignment needs " + std::to_string(kMinAlignPoints));
  return r;
}

}  // namespace headcast
