#include "training/guided_recording.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "common/core/image_io.h"
#include "common/core/log.h"
#include "common/core/options.h"
#include "common/core/timer.h"
#include "common/tracking/face_tracker.h"

namespace headcast {

void GuidedRecordingOptions::Check() const {
  OptionsCheck c("GuidedRecordingOptions");
  c.InRange("seconds", seconds, 1.0, 3600.0).That(!out_dir.empty(), "out_dir is required");
  c.InRange("check_every", check_every, 1, 1000).InRange("min_face_share", min_face_share, 0.0, 1.0);
  c.InRange("min_brightness", min_brightness, 0.0, 255.0).InRange("max_brightness", max_brightness, 0.0, 255.0);
  c.That(min_brightness < max_brightness, "min_brightness < max_brightness");
  c.InRange("min_turn_deg", min_turn_deg, 0.0, 60.0);
  c.ThrowIfErrors();
}

std::string GuidePrompt(double t, double total) {
  // The share of the time each prompt gets: turning and expressions are what
  // the avatar most needs to have seen.
  static const std::pair<double, const char*> kPhases[] = {
      {0.10, "Look at the camera and say a few words"},
      {0.35, "Turn your head slowly left and right"},
      {0.45, "Look up, then down"},
      {0.65, "Smile, raise your brows, open your mouth wide"},
      {0.80, "Blink a few times, look around with your eyes"},
      {1.00, "Talk naturally, as in a call"},
  };
  const double f = total > 0 ? t / total : 1;
  for (const auto& [until, text] : kPhases)
    if (f < until) return text;
  return kPhases[std::size(kPhases) - 1].second;
}

double ApproximateYawDeg(const Landmarks2d& l) {
  const Eigen::Vector2d mid = 0.5 * (l[36] + l[45]);
  const double eyes = (l[45] - l[36]).norm();
  if (!(eyes > 1)) return 0;
  // The nose tip stands about half the outer eye corners' distance in front
  // of them (faces and the built-in head alike), so its sideways offset is
  // that times sin(yaw).
  const double s = std::clamp((l[30].x() - mid.x()) / (0.5 * eyes), -1.0, 1.0);
  return std::asin(s) * 180 / M_PI;
}

nlohmann::json RecordingQuality::ToJson() const {
  return {{"frames", frames},
          {"seconds", seconds},
          {"checked_frames", checked},
          {"face_share", checked > 0 ? static_cast<double>(faces) / checked : 0.0},
          {"face_brightness", brightness},
          {"yaw_range_deg", {yaw_min_deg, yaw_max_deg}},
          {"yaw_note", "approximate, from the nose's offset between the eye corners"},
          {"ok", ok()},
          {"problems", problems}};
}

void JudgeRecording(const GuidedRecordingOptions& o, RecordingQuality* q) {
  q->problems.clear();
  const double share = q->checked > 0 ? static_cast<double>(q->faces) / q->checked : 0;
  char text[200];
  if (share < o.min_face_share) {
    std::snprintf(text, sizeof(text),
                  "a face was found in %.0f %% of the frames (needs %.0f %%): stay in the picture, face the camera",
                  100 * share, 100 * o.min_face_share);
    q->problems.push_back(text);
  }
  if (q->faces > 0 && q->brightness < o.min_brightness) {
    std::snprintf(text, sizeof(text), "the face is too dark (grey level %.0f, needs %.0f): add light in front of you",
                  q->brightness, o.min_brightness);
    q->problems.push_back(text);
  }
  if (q->faces > 0 && q->brightness > o.max_brightness) {
    std::snprintf(text, sizeof(text), "the face is too bright (grey level %.0f, at most %.0f): less direct light",
                  q->brightness, o.max_brightness);
    q->problems.push_back(text);
  }
  if (q->faces > 0 && (q->yaw_max_deg < o.min_turn_deg || q->yaw_min_deg > -o.min_turn_deg)) {
    std::snprintf(text, sizeof(text),
                  "the head turned %.0f° to one side and %.0f° to the other (needs %.0f° each way): turn further",
                  -q->yaw_min_deg, q->yaw_max_deg, o.min_turn_deg);
    q->problems.push_back(text);
  }
}

namespace {

void DrawGuide(const std::string& prompt, double left_s, const FaceObservation* face, cv::Mat* frame) {
  const int w = frame->cols;
  const double scale = std::max(0.5, w / 1000.0);
  cv::rectangle(*frame, cv::Rect(0, 0, w, static_cast<int>(56 * scale)), cv::Scalar(32, 32, 32), cv::FILLED);
  cv::putText(*frame, prompt, cv::Point(static_cast<int>(12 * scale), static_cast<int>(38 * scale)),
              cv::FONT_HERSHEY_SIMPLEX, 0.9 * scale, cv::Scalar(255, 255, 255),
              std::max(1, static_cast<int>(2 * scale)), cv::LINE_AA);
  char countdown[32];
  std::snprintf(countdown, sizeof(countdown), "%.0f s", std::ceil(left_s));
  cv::putText(*frame, countdown, cv::Point(w - static_cast<int>(90 * scale), static_cast<int>(38 * scale)),
              cv::FONT_HERSHEY_SIMPLEX, 0.9 * scale, cv::Scalar(120, 220, 255),
              std::max(1, static_cast<int>(2 * scale)), cv::LINE_AA);
  if (face != nullptr) {
    const bool found = face->status != FaceStatus::kNoFace;
    if (found) cv::rectangle(*frame, face->box, cv::Scalar(80, 220, 80), 2);
    if (!found)
      cv::putText(*frame, "no face - move into the picture", cv::Point(12, frame->rows - 20), cv::FONT_HERSHEY_SIMPLEX,
                  0.8 * scale, cv::Scalar(60, 60, 255), 2, cv::LINE_AA);
  }
}

}  // namespace

RecordingQuality RecordGuided(FrameSource& source, const GuidedRecordingOptions& o,
                              const std::function<bool(const cv::Mat&)>& show) {
  o.Check();
  FaceTrackerOptions face_options;
  if (!o.predictor.empty()) face_options.predictor_path = o.predictor;
  face_options.locate_irises = false;
  FaceTracker tracker(face_options);
  std::filesystem::create_directories(o.out_dir);
  RecordingQuality q;
  q.yaw_min_deg = 1e9;
  q.yaw_max_deg = -1e9;
  double brightness_sum = 0;
  Stopwatch watch;
  std::optional<FaceObservation> last_face;
  int skipped = 0;
  while (watch.ElapsedSeconds() < o.seconds) {
    CapturedFrame frame;
    std::string problem;
    const ReadStatus status = source.Read(&frame, &problem);
    if (status == ReadStatus::kEnd) break;
    if (status == ReadStatus::kSkipped) {
      if (++skipped % 30 == 1) spdlog::warn("recording: a frame was skipped ({})", problem);
      continue;
    }
    char name[32];
    std::snprintf(name, sizeof(name), "%05d.jpg", q.frames);
    if (!cv::imwrite((std::filesystem::path(o.out_dir) / name).string(), frame.bgr, {cv::IMWRITE_JPEG_QUALITY, 95}))
      throw std::runtime_error(o.out_dir + ": cannot write the recording's frames");
    if (q.frames % o.check_every == 0) {
      const FaceObservation face = tracker.Track(frame.bgr, frame.capture_time_s);
      ++q.checked;
      if (face.status != FaceStatus::kNoFace) {
        ++q.faces;
        cv::Mat grey;
        cv::cvtColor(frame.bgr(face.box & cv::Rect(0, 0, frame.bgr.cols, frame.bgr.rows)), grey, cv::COLOR_BGR2GRAY);
        brightness_sum += cv::mean(grey)[0];
        const double yaw = ApproximateYawDeg(face.raw);
        q.yaw_min_deg = std::min(q.yaw_min_deg, yaw);
        q.yaw_max_deg = std::max(q.yaw_max_deg, yaw);
      }
      last_face = face;
    }
    ++q.frames;
    if (show) {
      cv::Mat shown = frame.bgr.clone();
      DrawGuide(GuidePrompt(watch.ElapsedSeconds(), o.seconds), o.seconds - watch.ElapsedSeconds(),
                last_face ? &*last_face : nullptr, &shown);
      if (!show(shown)) break;
    }
  }
  q.seconds = watch.ElapsedSeconds();
  if (q.frames == 0) throw std::runtime_error(source.Describe() + ": no frame could be read to record");
  if (q.faces > 0) {
    q.brightness = brightness_sum / q.faces;
  } else {
    q.yaw_min_deg = q.yaw_max_deg = 0;
  }
  JudgeRecording(o, &q);
  return q;
}

}  // namespace headcast
