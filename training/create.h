// headcast-train create: one command from a video, an image folder or a camera
// to a person's avatar. It runs the stages a user would otherwise chain by
// hand — (record from a camera, with guidance and a quality check) → prep →
// fine-tune from the shipped general model → eval — in a work folder that
// remembers which stages finished, so an interrupted run continues (--resume).
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>

#include "common/capture/frame_source.h"
#include "training/avatar_fit.h"
#include "training/guided_recording.h"

namespace headcast {

struct CreateOptions {
  // A video file, an image folder, or a camera (/dev/videoN, v4l2:/dev/videoN).
  std::string input;
  std::string out;       // the avatar (.hcavatar)
  std::string work_dir;  // stages' outputs; "" = OUT without its extension + ".create"
  // "" = the shipped ICT-FaceKit model and its general model (models/).
  std::string head_model;
  std::string general;
  int iterations = 3000;   // fine-tune steps (creation stays under 30 min on two cores: bench/DEFAULTS.md)
  int resolution = 256;    // the avatar's output size
  int max_frames = 1000;   // frames of the input used (0: all)
  int test_frames = 150;   // held out for the figures, at most a sixth of the fitted frames
  int processes = 2;       // fine-tune ranks (CreateHooks::start_ranks starts the others)
  bool resume = false;     // continue the run in work_dir
  std::string stop_after;  // "", "record", "prep" or "fine-tune": end there (to look before training on)
  std::string intrinsics;  // camera fx,fy,cx,cy when known
  // The person's shape when known (an avatar, or headcast-fit-mesh's PARAMS.json
  // of a head scan) instead of calibrating it from the video.
  std::string identity_from;
  double shape_prior = -1;  // calibration's shape prior (HeadFitterOptions::shape_prior); < 0: its default
  bool landmarks = true;    // eval's dlib landmark figures
  // Cameras are recorded first: record_s seconds (0 = 60 for cameras, none for
  // files). A file given a record_s is read in real time as if it were a camera.
  double record_s = 0;
  bool accept_recording = false;  // go on when the recording's quality check fails
  SourceOptions source;
  DistributedOptions distributed;  // set on the fine-tune's other ranks (--rank > 0)
  int threads = 0;                 // libtorch threads of this process (0: libtorch's choice)
  void Check() const;
};

struct CreateHooks {
  // Starts the fine-tune's other ranks (options.processes > 1), fills
  // fit->distributed, and returns what waits for them. Programs start
  // processes; this library does not.
  std::function<std::function<void()>(FitOptions* fit)> start_ranks;
  // Shows a recording frame with its guidance; false = the user quit.
  std::function<bool(const cv::Mat&)> show;
};

// Whether `input` names a camera (recorded before training).
bool IsCameraInput(const std::string& input);

// Runs (or resumes) the whole creation and returns its summary: the avatar,
// held-out PSNR/SSIM and landmark figures, where the side-by-side video is,
// minutes per stage, and the receiver and sender commands that use the avatar.
// On a rank > 0 it runs only its share of the fine-tune and returns {}.
nlohmann::json RunCreate(const CreateOptions& options, const CreateHooks& hooks);

// The summary in lines a person reads (what RunCreate returned).
std::string CreateSummaryText(const nlohmann::json& summary);

}  // namespace headcast
