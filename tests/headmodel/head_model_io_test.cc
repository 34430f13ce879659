// The head-model .npz format: round trip, and clear refusals of bad files.
#include "common/headmodel/head_model_io.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/core/npy.h"
#include "tests/headmodel/test_models.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

using testing::Builtin;

class HeadModelIo : public ::testing::Test {
 protected:
  // The model is saved once for the suite; each test edits a copy.
  static void SetUpTestSuite() {
    path_ = (std::filesystem::temp_directory_path() / "headcast_tests" / "head_model_io_builtin.npz").string();
    std::filesystem::create_directories(std::filesystem::path(path_).parent_path());
    SaveHeadModel(Builtin(), path_);
  }
  void SetUp() override { dir_ = testing::TempDir("io"); }
  // Loads `path` expecting failure; returns the message.
  std::string LoadError(const std::string& path) {
    try {
      LoadHeadModel(path);
    } catch (const std::exception& e) {
      return e.what();
    }
    return "loaded without error";
  }
  // Writes a copy of the saved model with one key changed by `edit`.
  std::string Edited(const std::string& name, const std::function<void(NpzArchive*)>& edit) {
    NpzArchive a = ReadNpz(path_);
    edit(&a);
    const std::string out = dir_ + "/" + name + ".npz";
    WriteNpz(out, a, /*compress=*/false);
    return out;
  }
  std::string dir_;
  static std::string path_;
};
std::string HeadModelIo::path_;

TEST_F(HeadModelIo, RoundTripsExactly) {
  const HeadModel loaded = LoadHeadModel(path_);
  EXPECT_EQ(loaded.fingerprint(), Builtin().fingerprint());
  EXPECT_EQ(loaded.data().expression_names, Builtin().data().expression_names);
  EXPECT_EQ(loaded.data().texture_mean, Builtin().data().texture_mean);
  const HeadModelParams p = testing::RandomParams(Builtin(), 9);
  EXPECT_EQ((loaded.Forward(p).vertices - Builtin().Forward(p).vertices).cwiseAbs().maxCoeff(), 0.f);
  EXPECT_EQ(LoadHeadModelSpec("builtin").fingerprint(), Builtin().fingerprint());
  EXPECT_FALSE(loaded.data().HasExpressionRange());  // PCA-style: no range, none written
}

TEST_F(HeadModelIo, ExpressionRangeIsCheckedWhenPresent) {
  const std::string p = Edited("range", [](NpzArchive* a) {
    const float backwards[2] = {1.f, 0.f};
    (*a)["expression_range"] = NpyArray::From<float>({2}, backwards);
  });
  const std::string e = LoadError(p);
  EXPECT_NE(e.find("expression_range"), std::string::npos) << e;
}

TEST_F(HeadModelIo, MissingKey) {
  const std::string p = Edited("missing", [](NpzArchive* a) { a->erase("f"); });
  const std::string e = LoadError(p);
  EXPECT_NE(e.find("missing.npz"), std::string::npos) << e;
  EXPECT_NE(e.find("'f'"), std::string::npos) << e;
  EXPECT_NE(e.find("missing"), std::string::npos) << e;
}

TEST_F(HeadModelIo, WrongShape) {
  const std::string p = Edited("shape", [](NpzArchive* a) {
    std::vector<float> v(12, 0.f);
    (*a)["weights"] = NpyArray::From<float>({4, 3}, v.data());
  });
  const std::string e = LoadError(p);
  EXPECT_NE(e.find("'weights'"), std::string::npos) << e;
  EXPECT_NE(e.find("shape (4, 3)"), std::string::npos) << e;
}

TEST_F(HeadModelIo, NaNValues) {
  const std::string p =
      Edited("nan", [](NpzArchive* a) { (*a)["v_template"].mutable_data<float>()[7] = std::nanf(""); });
  const std::string e = LoadError(p);
  EXPECT_NE(e.find("'v_template'"), std::string::npos) << e;
  EXPECT_NE(e.find("NaN"), std::string::npos) << e;
}

TEST_F(HeadModelIo, WrongDtypeAndVersion) {
  std::string e = LoadError(Edited("dtype", [](NpzArchive* a) {
    const auto v = (*a)["f"].ToFloats();
    (*a)["f"] = NpyArray::From<float>((*a)["f"].shape(), v.data());
  }));
  EXPECT_NE(e.find("expected int32 or int64"), std::string::npos) << e;
  e = LoadError(Edited("version", [](NpzArchive* a) {
    const int32_t v = 99;
    (*a)["headcast_format"] = NpyArray::From<int32_t>({1}, &v);
  }));
  EXPECT_NE(e.find("version 99"), std::string::npos) << e;
}

TEST_F(HeadModelIo, BadIndicesAreCaught) {
  const std::string e = LoadError(Edited("index", [](NpzArchive* a) { (*a)["f"].mutable_data<int32_t>()[5] = -3; }));
  EXPECT_NE(e.find("index.npz"), std::string::npos) << e;
  EXPECT_NE(e.find("'f'"), std::string::npos) << e;
}

TEST_F(HeadModelIo, TruncatedAndMissingFiles) {
  const std::string cut = dir_ + "/cut.npz";
  std::filesystem::copy_file(path_, cut);
  std::filesystem::resize_file(cut, std::filesystem::file_size(path_) / 3);
  std::string e = LoadError(cut);
  EXPECT_NE(e.find("cut.npz"), std::string::npos) << e;
  e = LoadError(dir_ + "/nope.npz");
  EXPECT_NE(e.find("nope.npz"), std::string::npos) << e;
  EXPECT_NE(e.find("no such file"), std::string::npos) << e;
  { std::ofstream(dir_ + "/text.npz") << "v 1 2 3\n"; }
  e = LoadError(dir_ + "/text.npz");
  EXPECT_NE(e.find("text.npz"), std::string::npos) << e;
}

}  // namespace
}  // namespace headcast
