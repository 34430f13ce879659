// Opening a frame source from its spec.
#include "common/capture/frame_source.h"

#include <filesystem>

#include "common/capture/recorded_sources.h"
#include "common/capture/stereo_depth.h"
#include "common/capture/v4l2_source.h"
#include "common/core/options.h"

namespace headcast {

namespace fs = std::filesystem;

void SourceOptions::Check() const {
  OptionsCheck c("SourceOptions");
  c.InRange("fps", fps, 0.1, 1000).InRange("width", width, 16, 16384).InRange("height", height, 16, 16384);
  c.That(pixel_format == "auto" || pixel_format == "yuyv" || pixel_format == "mjpeg",
         "pixel_format must be auto, yuyv or mjpeg");
  c.InRange("depth_scale", depth_scale, 0.05, 1).Positive("depth_units_per_metre", depth_units_per_metre);
  c.ThrowIfErrors();
}

std::unique_ptr<FrameSource> OpenFrameSource(const std::string& spec, const SourceOptions& options) {
  options.Check();
  if (spec.rfind("zed:", 0) == 0) {
    if (options.stereo_calibration.empty())
      throw std::runtime_error(spec + ": a stereo source needs a calibration (--stereo-calibration FILE)");
    const StereoCalibration calibration = ReadStereoCalibration(options.stereo_calibration, options.stereo_resolution);
    SourceOptions inner = options;
    inner.width = 2 * calibration.size.width;  // side by side
    inner.height = calibration.size.height;
    return std::make_unique<StereoDepthSource>(OpenFrameSource(spec.substr(4), inner), calibration, options);
  }
  if (spec.rfind("v4l2:", 0) == 0) return std::make_unique<V4l2Source>(spec.substr(5), options);
  if (spec.rfind("/dev/video", 0) == 0) return std::make_unique<V4l2Source>(spec, options);
  if (!options.depth_input.empty()) return std::make_unique<RgbdFolderSource>(options.depth_input, options);
  if (fs::is_directory(spec)) {
    for (const char* name : {"associations.txt", "associate.txt"})
      if (fs::exists(fs::path(spec) / name))
        return std::make_unique<RgbdFolderSource>((fs::path(spec) / name).string(), options);
    return std::make_unique<ImageFolderSource>(spec, options);
  }
  if (!fs::exists(spec)) throw std::runtime_error(spec + ": no such file, folder or camera");
  return std::make_unique<VideoFileSource>(spec, options);
}

}  // namespace headcast
