// The head-model .npz format: round trip, and clear refusals of bad files.
#include "common/headmodel/head_model_io.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>

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

namespace headcast {

// The compact form shipped models use: bases as int16 steps plus KEY_step.
TEST_F(HeadModelIo, CompactBasesRoundTripWithinHalfAStep) {
  const double step = 5e-6;
  const std::string compact = dir_ + "/compact.npz";
  SaveHeadModel(Builtin(), compact, {step});
  const NpzArchive a = ReadNpz(compact);
  EXPECT_EQ(a.at("shapedirs").dtype(), DType::kInt16);
  EXPECT_EQ(a.at("expressiondirs").dtype(), DType::kInt16);
  EXPECT_LT(std::filesystem::file_size(compact), std::filesystem::file_size(path_));
  const HeadModel back = LoadHeadModel(compact);
  const HeadModelData &d = Builtin().data(), &b = back.data();
  EXPECT_LE((d.shapedirs - b.shapedirs).cwiseAbs().maxCoeff(), step / 2 * 1.0001);
  EXPECT_LE((d.expressiondirs - b.expressiondirs).cwiseAbs().maxCoeff(), step / 2 * 1.0001);
  EXPECT_GT((d.expressiondirs - b.expressiondirs).cwiseAbs().maxCoeff(), 0.0);  // it did quantise
  EXPECT_EQ(back.fingerprint(), Builtin().fingerprint());
  EXPECT_EQ(b.v_template, d.v_template);  // only the bases are compact
}

TEST_F(HeadModelIo, CompactBasesRefuseWhatDoesNotFit) {
  try {
    SaveHeadModel(Builtin(), dir_ + "/fine.npz", {1e-9});  // centimetres in int16 steps of a nanometre
    FAIL() << "a step too fine for int16 was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("needs a step of at least"), std::string::npos) << e.what();
  }
  EXPECT_THROW(SaveHeadModel(Builtin(), dir_ + "/neg.npz", {-1e-6}), std::invalid_argument);
  const std::string compact = dir_ + "/compact.npz";
  SaveHeadModel(Builtin(), compact, {5e-6});
  NpzArchive a = ReadNpz(compact);
  // An int16 basis without its step, and a step that is not a positive number, are refused by name.
  NpzArchive no_step = a;
  no_step.erase("expressiondirs_step");
  WriteNpz(dir_ + "/no_step.npz", no_step);
  EXPECT_NE(LoadError(dir_ + "/no_step.npz").find("expressiondirs_step"), std::string::npos);
  for (const float bad : {0.f, -1e-6f, std::numeric_limits<float>::quiet_NaN()}) {
    NpzArchive b = a;
    b["shapedirs_step"] = NpyArray::From<float>({1}, &bad);
    WriteNpz(dir_ + "/bad_step.npz", b);
    EXPECT_NE(LoadError(dir_ + "/bad_step.npz").find("shapedirs_step"), std::string::npos) << bad;
  }
}

}  // namespace headcast
