// Recording a person for their avatar from a camera: the frames go to an image
// folder (JPEG at quality 95: the training targets should not carry a video
// codec's blur) while the person follows prompts (turn the head, talk, smile, blink, look
// around), and a quality check says whether the recording can make a good
// avatar (a face in nearly every frame, enough light, the head turned both
// ways) before minutes of training are spent on it.
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "common/capture/frame_source.h"
#include "common/tracking/head_fitter.h"

namespace headcast {

struct GuidedRecordingOptions {
  double seconds = 60;
  std::string out_dir;    // the recording: 00000.jpg, 00001.jpg, ...
  std::string predictor;  // dlib's 68-point predictor ("" = the tracker's default)
  int check_every = 3;    // frames between face checks (the check runs while recording)
  // The quality check.
  double min_face_share = 0.9;                       // of the checked frames
  double min_brightness = 50, max_brightness = 210;  // mean grey level in the face box, 0..255
  double min_turn_deg = 15;                          // the head turned at least this far to each side
  void Check() const;
};

// The prompt shown `t` seconds into a recording of `total` seconds: the phases
// (look at the camera and talk; turn left and right; look up and down; smile,
// raise the brows, open the mouth wide; blink and look around; talk) share the
// time in fixed proportions.
std::string GuidePrompt(double t, double total);

// Head yaw in degrees estimated from 68 landmarks (pixels): the nose tip's
// offset from the eye corners' midpoint over the eye-corner distance. Rough
// (a few degrees), enough to tell whether the head turned; sign: positive when
// the nose moves to the image's right.
double ApproximateYawDeg(const Landmarks2d& landmarks);

struct RecordingQuality {
  int frames = 0;         // recorded
  int checked = 0;        // frames the face check ran on
  int faces = 0;          // of those, with a face
  double brightness = 0;  // mean grey level in the face boxes
  double yaw_min_deg = 0, yaw_max_deg = 0;
  double seconds = 0;
  std::vector<std::string> problems;  // what fails the check, in words a person can act on
  bool ok() const { return problems.empty(); }
  nlohmann::json ToJson() const;
};

// The check's verdict on measured figures (fills `problems`).
void JudgeRecording(const GuidedRecordingOptions& options, RecordingQuality* quality);

// Records `options.seconds` of `source` to options.out_dir, calling `show`
// with each frame drawn with its prompt, a countdown and the face box (false
// from show ends the recording early). Throws when the source gives no frame.
RecordingQuality RecordGuided(FrameSource& source, const GuidedRecordingOptions& options,
                              const std::function<bool(const cv::Mat&)>& show);

}  // namespace headcast
