// Expression fidelity of an avatar, measured the way a viewer judges it: dlib's
// 68 landmarks detected on the avatar's picture against those detected on the
// true frame, per face region, in units of the true eye distance; and how the
// eye opening (blinks) of the avatar follows the person's, and where its
// irises look against the person's (gaze). Given the fitted head's landmarks
// too, each picture's points are also set against the fit's: on an
// expressive frame that tells which link of the chain lost the expression —
// the fit (the truth far from it) or the avatar (its picture far from the
// mesh it was driven with).
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
  // One frame: the true picture and the avatar's (same size and framing),
  // and optionally the fitted head model's 68 landmarks projected into them.
  void Add(const cv::Mat& truth_bgr, const cv::Mat& avatar_bgr, const Landmarks2d* fitted = nullptr);
  // {frames, found_in_both, error_iod: {eyes, brows, nose, mouth, jaw, all},
  //  blink: {correlation, truth_opening_sd},
  //  gaze: {eyes, correlation_x, correlation_y, error, truth_sd_x, truth_sd_y},
  //  and with fitted landmarks fit: {frames, truth_vs_fit, avatar_vs_fit,
  //  truth_vs_fit_moving, avatar_vs_fit_moving} (error_iod's regions each)}.
  //  The "moving" figures leave out each point's mean offset from the fit
  //  over the frames: dlib's points and the head model's landmark embedding
  //  differ by a steady amount (on training frames too), and what is left
  //  is how each picture departs from the fit's motion.
  // Gaze is the iris in its eye's frame (IrisInEyeFrame: eye widths), over the
  // eyes whose iris was found in both pictures.
  nlohmann::json Summary() const;

 private:
  bool Detect(const cv::Mat& image, FaceObservation* out);
  FaceTracker tracker_;
  int frames_ = 0;
  std::vector<std::array<double, 5>> region_errors_;  // per frame found in both
  // Per such frame with fitted landmarks: each point's offset from the fit, in eye distances.
  std::vector<Landmarks2d> truth_from_fit_, avatar_from_fit_;
  std::vector<double> truth_opening_, avatar_opening_;
  std::vector<double> truth_gaze_[2], avatar_gaze_[2];  // x, y per eye seen in both
};

}  // namespace headcast
