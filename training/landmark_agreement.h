// Expression fidelity of an avatar, measured the way a viewer judges it: dlib's
// 68 landmarks detected on the avatar's picture against those detected on the
// true frame, per face region, in units of the true eye distance; and how the
// eye opening (blinks) of the avatar follows the person's, and where its
// irises look against the person's (gaze).
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "common/tracking/face_tracker.h"

namespace headcast {

// Pearson correlation of two equally long series; 0 when either is constant or shorter than 3.
double PearsonCorrelation(const std::vector<double>& a, const std::vector<double>& b);
// Sample standard deviation; 0 for fewer than 2 values.
double StandardDeviation(const std::vector<double>& v);

// Eye opening of one 68-point set: the two vertical lid distances over the
// eye's width, both eyes averaged (about 0.3 open, under 0.1 closed).
double EyeOpening(const Landmarks2d& landmarks);

class LandmarkAgreement {
 public:
  // Throws std::runtime_error when dlib's shape predictor cannot be read.
  explicit LandmarkAgreement(const std::string& predictor_path);
  ~LandmarkAgreement();
  // One frame: the true picture and the avatar's (same size and framing).
  void Add(const cv::Mat& truth_bgr, const cv::Mat& avatar_bgr);
  // {frames, found_in_both, error_iod: {eyes, brows, nose, mouth, jaw, all},
  //  blink: {correlation, truth_opening_sd},
  //  gaze: {eyes, correlation_x, correlation_y, error, truth_sd_x, truth_sd_y}}.
  // Gaze is the iris in its eye's frame (IrisInEyeFrame: eye widths), over the
  // eyes whose iris was found in both pictures.
  nlohmann::json Summary() const;

 private:
  bool Detect(const cv::Mat& image, FaceObservation* out);
  FaceTracker tracker_;
  int frames_ = 0;
  std::vector<std::array<double, 5>> region_errors_;  // per frame found in both
  std::vector<double> truth_opening_, avatar_opening_;
  std::vector<double> truth_gaze_[2], avatar_gaze_[2];  // x, y per eye seen in both
};

}  // namespace headcast
