#include "common/core/shipped_models.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

namespace headcast {
namespace fs = std::filesystem;

std::vector<std::string> ShippedModelFolders() {
  std::vector<std::string> folders;
  if (const char* env = std::getenv("HEADCAST_MODELS"); env != nullptr && *env != '\0') folders.push_back(env);
  std::error_code error;
  const fs::path exe = fs::read_symlink("/proc/self/exe", error);
  if (!error) {
    const fs::path bin = exe.parent_path();
    folders.push_back((bin / ".." / "share" / "headcast" / "models").lexically_normal().string());
    folders.push_back((bin / ".." / ".." / "models").lexically_normal().string());
  }
  return folders;
}

std::string ShippedModelPath(const std::string& name) {
  std::string looked;
  for (const std::string& folder : ShippedModelFolders()) {
    const fs::path path = fs::path(folder) / name;
    std::error_code error;
    if (fs::is_regular_file(path, error)) return path.string();
    looked += (looked.empty() ? "" : ", ") + folder;
  }
  throw std::runtime_error("the shipped model " + name + " is not in " + (looked.empty() ? "any folder" : looked) +
                           " (set HEADCAST_MODELS to the repository's models/ folder, or make it with "
                           "deploy/make_default_models.sh)");
}

std::string SiblingProgram(const std::string& name) {
  std::error_code error;
  const fs::path bin = fs::read_symlink("/proc/self/exe", error).parent_path();
  if (error || bin == "/usr/bin" || bin == "/usr/local/bin" || bin == "/bin") return name;
  return (bin / name).string();
}

}  // namespace headcast
