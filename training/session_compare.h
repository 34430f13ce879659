// What the other end of a session saw, against what the camera saw: the
// parameters a receiver recorded (--record), rendered with the avatar through
// the receiver's render path, each beside the input frame it was tracked from,
// cut to the avatar's framing (its camera contract) and masked as a training
// target is. The demo uses it to report the avatar's PSNR against the truth.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace headcast {

struct CompareOptions {
  std::string head_model = "builtin";
  std::string avatar;     // .hcavatar with a camera contract
  std::string recording;  // the receiver's --record (.hcrec)
  std::string truth;      // the input the sender tracked: a video or an image folder
  // The sender's --frames-csv (sequence,input_frame per sent frame). Without
  // it, sequence k is input frame k (a source read without skipping).
  std::string frame_map;
  std::string out_dir;
  std::string caption;  // a line under the panels (e.g. the session's figures)
  void Check() const;
};

// Writes compare.json, per_frame.csv and side_by_side.mp4 (input | head-model
// fit | avatar, labelled) to out_dir; returns the report. Throws with a clear
// message on a frame map that is not one, input shorter than the recording,
// another head model's recording, or an avatar without a camera contract.
nlohmann::json RunCompare(const CompareOptions& options);

}  // namespace headcast
