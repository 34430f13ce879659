// libFuzzer target: the files headcast reads from elsewhere, on arbitrary
// bytes. The first byte picks the reader: an .npy array, an .npz (zip)
// archive, a parameter recording (.hcrec), a token file, an avatar manifest
// (its config, subject camera, camera contract and tracking anchor), a --config file. Each must refuse bad
// bytes with an exception and never crash, hang or allocate what the bytes
// merely claim (libFuzzer's -rss_limit_mb catches that).
#include <sys/mman.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>

#include "common/avatar/avatar_config.h"
#include "common/core/camera.h"
#include "common/core/npy.h"
#include "common/headmodel/params.h"
#include "common/tracking/anchor_reference.h"
#include "common/tracking/expression_fit.h"
#include "proto/protocol.h"
#include "proto/recording.h"

namespace {

// The bytes as a file the readers can open by name (memory only).
class MemoryFile {
 public:
  MemoryFile(const uint8_t* data, size_t size) : fd_(memfd_create("fuzz", 0)) {
    if (fd_ < 0 || write(fd_, data, size) != static_cast<ssize_t>(size)) std::abort();
  }
  ~MemoryFile() { close(fd_); }
  std::string path() const { return "/proc/self/fd/" + std::to_string(fd_); }

 private:
  int fd_;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const uint8_t which = data[0] % 6;
  ++data;
  --size;
  try {
    switch (which) {
      case 0:
        headcast::ParseNpy(std::string(reinterpret_cast<const char*>(data), size), "fuzz.npy");
        break;
      case 1:
        headcast::ReadNpz(MemoryFile(data, size).path());
        break;
      case 2: {
        headcast::RecordingReader reader(MemoryFile(data, size).path());
        headcast::FrameParams f;
        for (int i = 0; i < 10000 && reader.Next(&f); ++i) {
        }
        break;
      }
      case 3:
        headcast::ReadTokenFile(MemoryFile(data, size).path());
        break;
      case 4: {
        // Each entry read on its own, as the readers of an avatar file do.
        const nlohmann::json manifest = nlohmann::json::parse(data, data + size);
        const std::function<void()> entries[] = {
            [&] { headcast::AvatarConfig::FromJson(manifest.at("config")); },
            [&] { headcast::CameraFromJson(manifest.at("subject").at("intrinsics")); },
            [&] { headcast::CameraContract::FromJson(manifest.at("camera")); },
            [&] { headcast::AnchorReference::FromJson(manifest.at("tracking_anchor")); },
            [&] { headcast::ExpressionFitSettings::FromJson(manifest.at("tracking_fit")); }};
        for (const auto& read : entries) {
          try {
            read();
          } catch (const std::exception&) {
            // refused
          }
        }
        break;
      }
      case 5: {
        std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
        CLI::ConfigTOML().from_config(in);
        break;
      }
    }
  } catch (const std::exception&) {
    // refused: what bad bytes must get
  }
  return 0;
}
