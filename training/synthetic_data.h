// Synthetic training samples made on the fly (METHOD §5): the head model
// rendered with albedo and SH light under randomly drawn parameters — never a
// fixed dataset on disk.
#pragma once

#include <opencv2/core.hpp>
#include <random>

#include "common/headmodel/head_model.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/params.h"

namespace headcast {

struct SyntheticDataOptions {
  int image_size = 128;                                      // rendered image edge, pixels
  double fov_y_deg = 24;                                     // camera field of view, degrees
  double noise = 0.3;                                        // U[-noise, noise] added to beta, psi, tau (METHOD: 0.3)
  double coefficient_limit = 2;                              // clamp of beta, psi, tau (METHOD: [-2, 2])
  double base_expression = 1.0;                              // base psi drawn in [-b, b] before the noise
  double neck_x_deg = 80, neck_y_deg = 60, neck_z_deg = 80;  // uniform neck ranges (METHOD §5)
  double jaw_max_rad = 0.35;                                 // jaw opening drawn in [0, max]
  double distance_min = 0.55, distance_max = 0.75;           // camera distance, metres
  double camera_yaw_deg = 10, camera_pitch_deg = 8;          // camera placement jitter, degrees
  double light_jitter = 0.25;                                // relative jitter of the SH light
  bool vary_identity = true;                                 // false: keep the given subject's beta and tau
  void Check() const;
};

struct SyntheticSample {
  cv::Mat image_bgr;  // CV_8UC3
  cv::Mat mask;       // CV_8U, 255 on the head
  FrameParams frame;
  SubjectParams subject;
};

class SyntheticData {
 public:
  SyntheticData(const HeadModel& model, const SyntheticDataOptions& options, const SubjectParams& base_subject,
                uint64_t seed);
  SyntheticSample Next();
  // The same sample for the same index (evaluation sets), independent of Next().
  SyntheticSample At(uint64_t index) const;

 private:
  SyntheticSample Make(std::mt19937_64& rng) const;
  const HeadModel& model_;
  SyntheticDataOptions options_;
  SubjectParams base_;
  uint64_t seed_;
  std::mt19937_64 rng_;
};

}  // namespace headcast
