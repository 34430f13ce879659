// Test data location.
#include "tests/testing/test_data.h"

#include <cstdlib>
#include <filesystem>

namespace headcast::testing {

std::string DataDir() {
  namespace fs = std::filesystem;
  if (const char* env = std::getenv("HEADCAST_DATA"); env && fs::is_directory(env)) return env;
  const char* src = std::getenv("HEADCAST_SOURCE_DIR");
  const fs::path base = src ? fs::path(src) : fs::current_path();
  const fs::path shared = base / ".." / "shared" / "data";
  if (fs::is_directory(shared)) return fs::weakly_canonical(shared).string();
  return "";
}

std::string TempDir(const std::string& name) {
  namespace fs = std::filesystem;
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  fs::path dir =
      fs::temp_directory_path() / "headcast_tests" /
      (std::string(info ? info->test_suite_name() : "suite") + "." + (info ? info->name() : "test") + "." + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

}  // namespace headcast::testing
