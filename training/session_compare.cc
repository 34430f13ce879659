// headcast-train compare: a session's received parameters against the input.
#include "training/session_compare.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

#include "common/avatar/avatar.h"
#include "common/capture/frame_source.h"
#include "common/core/check.h"
#include "common/core/image_io.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/head_render.h"
#include "common/tracking/frame_mask.h"
#include "common/tracking/head_fitter.h"
#include "proto/recording.h"
#include "training/avatar_fit.h"
#include "training/dataset.h"
#include "training/run_report.h"

namespace fs = std::filesystem;

namespace headcast {

void CompareOptions::Check() const {
  OptionsCheck c("compare");
  c.That(!avatar.empty(), "an avatar (.hcavatar) is required");
  c.That(!recording.empty(), "a recording (the receiver's --record) is required");
  c.That(!truth.empty(), "the input (--truth: the video or image folder the sender tracked) is required");
  c.That(!out_dir.empty(), "an output folder is required");
  c.ThrowIfErrors();
}

namespace {

// sequence -> input frame, from the sender's --frames-csv.
std::map<uint64_t, int64_t> ReadFrameMap(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot be read");
  std::string line;
  if (!std::getline(in, line) || line.rfind("sequence,input_frame", 0) != 0)
    throw std::runtime_error(path + ": not a sender --frames-csv (its first line is not 'sequence,input_frame')");
  std::map<uint64_t, int64_t> map;
  for (int n = 2; std::getline(in, line); ++n) {
    if (line.empty()) continue;
    std::istringstream row(line);
    long long sequence = -1, frame = -1;
    char comma = 0;
    if (!(row >> sequence >> comma >> frame) || comma != ',' || sequence < 0 || frame < 0 || !(row >> std::ws).eof())
      throw std::runtime_error(path + ":" + std::to_string(n) + ": not 'sequence,input_frame': " + line);
    if (!map.emplace(sequence, frame).second)
      throw std::runtime_error(path + ":" + std::to_string(n) + ": sequence " + std::to_string(sequence) + " twice");
  }
  return map;
}

void Label(cv::Mat* panel, const std::string& text) {
  const double scale = 0.5 * panel->cols / 256.0;
  const int thickness = std::max(1, static_cast<int>(std::lround(scale * 2)));
  int baseline = 0;
  const cv::Size size = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, thickness, &baseline);
  cv::rectangle(*panel, cv::Rect(0, 0, size.width + 10, size.height + baseline + 8), cv::Scalar(0, 0, 0), cv::FILLED);
  cv::putText(*panel, text, cv::Point(5, size.height + 4), cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(255, 255, 255),
              thickness, cv::LINE_AA);
}

// A strip under the panels with `text`, shrunk to fit the width.
cv::Mat CaptionStrip(const std::string& text, int width) {
  cv::Mat strip(28, width, CV_8UC3, cv::Scalar(0, 0, 0));
  double scale = 0.5;
  int baseline = 0;
  while (scale > 0.25 && cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, 1, &baseline).width > width - 10)
    scale -= 0.025;
  cv::putText(strip, text, cv::Point(5, 19), cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
  return strip;
}

}  // namespace

nlohmann::json RunCompare(const CompareOptions& o) {
  o.Check();
  const HeadModel model = LoadHeadModelSpec(o.head_model);
  Avatar avatar = Avatar::Load(o.avatar, model);
  if (!avatar.camera_contract())
    throw std::runtime_error(o.avatar +
                             ": records no camera contract (the framing of its training frames); "
                             "recreate it with headcast-train create or subject");
  const CameraContract contract = *avatar.camera_contract();
  const SubjectParams& subject = avatar.subject();
  const int size = avatar.config().output_size;

  RecordingInfo info;
  std::vector<FrameParams> frames = ReadRecording(o.recording, &info);
  if (info.head_model_fingerprint != model.fingerprint())
    throw std::runtime_error(o.recording + ": recorded for head model " + info.head_model_name + ", not " +
                             model.data().name);
  if (frames.empty()) throw std::runtime_error(o.recording + ": no frames");

  // Each received frame's input frame; read in input order.
  const std::map<uint64_t, int64_t> map =
      o.frame_map.empty() ? std::map<uint64_t, int64_t>{} : ReadFrameMap(o.frame_map);
  std::vector<std::pair<int64_t, FrameParams>> wanted;
  for (const FrameParams& f : frames) {
    int64_t input = static_cast<int64_t>(f.sequence);
    if (!o.frame_map.empty()) {
      const auto it = map.find(f.sequence);
      if (it == map.end())
        throw std::runtime_error(o.frame_map + ": no input frame for sequence " + std::to_string(f.sequence) +
                                 " (is it this session's --frames-csv?)");
      input = it->second;
    }
    wanted.emplace_back(input, f);
    // A sender may stream fewer components (--expression-components): the rest are zero.
    wanted.back().second.expression = Resized(f.expression, model.num_expression());
  }
  std::stable_sort(wanted.begin(), wanted.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

  const HeadIdentity identity = model.MakeIdentity(subject.shape.cast<double>());
  HeadFitter fitter(model, HeadFitterOptions{});
  fitter.SetIdentity(subject.shape.cast<double>());
  HeadRenderOptions render_options;
  std::copy(subject.light.begin(), subject.light.end(), render_options.light.begin());
  const cv::Mat albedo = AlbedoTexture(model, subject.texture.cast<double>());
  const PrepOptions prep;  // the masks of training targets

  std::unique_ptr<FrameSource> source = OpenFrameSource(o.truth, SourceOptions{});
  CapturedFrame current;
  bool have_current = false;
  // The input frame `index` and its head mask (made on the full frame, as
  // prep's are), cut to the avatar's framing; empty when that frame was
  // unreadable; throws when the input ends first.
  struct Cut {
    cv::Mat image, mask;
  };
  auto input_cut = [&](int64_t index, const FrameParams& f) -> Cut {
    while (!have_current || static_cast<int64_t>(current.index) < index) {
      std::string why;
      const ReadStatus st = source->Read(&current, &why);
      if (st == ReadStatus::kEnd)
        throw std::runtime_error(o.truth + ": ends before input frame " + std::to_string(index) +
                                 " (is it the input this recording was tracked from?)");
      have_current = st == ReadStatus::kFrame;
    }
    if (static_cast<int64_t>(current.index) != index) return {};  // unreadable
    const std::optional<PinholeCamera> full = ContractCameraFor(contract, current.bgr.cols, current.bgr.rows);
    if (!full)
      throw std::runtime_error(o.truth + ": frames of " + std::to_string(current.bgr.cols) + "x" +
                               std::to_string(current.bgr.rows) + " are not of the avatar's camera (" +
                               std::to_string(contract.source.width) + "x" + std::to_string(contract.source.height) +
                               ")");
    const double s = static_cast<double>(current.bgr.cols) / contract.source.width;
    const double x0 = s * contract.crop_x0, y0 = s * contract.crop_y0, side = s * contract.crop_side;
    Cut cut{CropSquare(current.bgr, x0, y0, side, size, cv::INTER_AREA),
            CropGrabCutMask(current.bgr, fitter.Project(f, *full), {x0, y0, side, size, subject.intrinsics})};
    return cut;
  };

  std::vector<FrameParams> ordered;
  for (const auto& w : wanted) ordered.push_back(w.second);
  cv::Mat input_panel, fit_panel;  // the frame being scored, from its target to its video frame
  fs::create_directories(o.out_dir);
  const fs::path dir = o.out_dir;
  VideoWriter video((dir / "side_by_side.mp4").string(), 30);
  std::ofstream csv(dir / "per_frame.csv");
  csv << "sequence,input_frame,psnr,ssim\n";
  ProgressLine progress(0, static_cast<int>(ordered.size()), 10, "frame");
  int done = 0;
  std::vector<int> scored;
  const EvalResult e = EvaluateOnFrames(
      avatar, model, subject, ordered,
      [&](int k) -> cv::Mat {
        progress.Show(done++, "comparing");
        const FrameParams& f = ordered[k];
        Cut cut = input_cut(wanted[k].first, f);
        if (cut.image.empty()) return cv::Mat();
        HeadModelOutput posed;
        model.Forward(identity, f.expression.cast<double>(), f.HeadPose(), &posed);
        input_panel = cut.image;
        fit_panel =
            RenderHead(model, posed.vertices, f.CamFromHead(), subject.intrinsics, albedo, render_options).image_bgr;
        return MaskedTarget(cut.image, CutCropMask(cut.mask, model, posed, fitter.Project(f, subject.intrinsics), f,
                                                   subject.intrinsics, prep.matte_rules()));
      },
      [&](int k, const cv::Mat& target, const cv::Mat& shown) {
        scored.push_back(k);
        cv::Mat input = input_panel.clone(), avatar_panel = shown.clone();
        Label(&input, "input");
        Label(&fit_panel, "head-model fit");
        char text[64];
        std::snprintf(text, sizeof(text), "avatar %.1f dB", cv::PSNR(target, shown));
        Label(&avatar_panel, text);
        cv::Mat row;
        cv::hconcat(std::vector<cv::Mat>{input, fit_panel, avatar_panel}, row);
        if (!o.caption.empty()) cv::vconcat(row, CaptionStrip(o.caption, row.cols), row);
        video.Write(row);
      });
  progress.Finish();
  video.Close();
  if (e.count == 0) throw std::runtime_error(o.truth + ": none of the recording's input frames could be read");
  for (int i = 0; i < e.count; ++i) {
    const int k = scored[i];
    csv << ordered[k].sequence << "," << wanted[k].first << "," << e.psnr[i] << "," << e.ssim[i] << "\n";
  }
  // The worst 5 % of frames: where a viewer sees the avatar fail.
  std::vector<double> sorted = e.psnr;
  std::sort(sorted.begin(), sorted.end());
  const size_t worst = std::max<size_t>(1, sorted.size() / 20);
  double worst_mean = 0;
  for (size_t i = 0; i < worst; ++i) worst_mean += sorted[i] / worst;
  nlohmann::json report = {
      {"frames", e.count},
      {"frames_received", frames.size()},
      {"psnr_db", e.psnr_mean},
      {"ssim", e.ssim_mean},
      {"psnr_db_worst_5_percent", worst_mean},
      {"render_ms_median", e.ms_median},
      {"resolution", size},
      {"how",
       "each received frame rendered with the avatar (the receiver's render path) against the input frame it was "
       "tracked from, cut to the avatar's framing, the background replaced as in training (head mask within the "
       "fitted model's reach, cleared below the jaw line)"},
      {"videos", {"side_by_side.mp4: input | head-model fit | avatar (PSNR per frame)"}}};
  std::ofstream(dir / "compare.json") << report.dump(2) << "\n";
  return report;
}

}  // namespace headcast
