// Parameter recordings and proto conversions.
#include "proto/recording.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_outline.h"
#include "common/headmodel/synthetic_motion.h"
#include "proto/convert.h"
#include "proto/recording_tools.h"
#include "tests/testing/test_data.h"

namespace headcast {
namespace {

const HeadModel& Model() {
  static const HeadModel m = MakeBuiltinHead();
  return m;
}

RecordingInfo Info() {
  RecordingInfo info;
  info.head_model_name = "builtin";
  info.head_model_fingerprint = Model().fingerprint();
  info.num_expression = Model().num_expression();
  info.fps = 30;
  info.subject.shape = Eigen::VectorXf::LinSpaced(12, -1, 1);
  info.subject.texture = Eigen::VectorXf::Ones(5);
  info.subject.light[0] = 2.5f;
  info.subject.intrinsics = PinholeCamera::FromFovY(256, 256, 24);
  info.source = "test";
  return info;
}

TEST(Convert, FrameParamsRoundTripAndLengthChecks) {
  FrameParams p = SyntheticTalkingHead(Model(), 17);
  p.confidence = 0.75f;
  v1::FrameParams m;
  ToProto(p, &m);
  FrameParams back;
  ASSERT_TRUE(FromProto(m, &back));
  EXPECT_EQ(back.expression, p.expression);
  EXPECT_EQ(back.jaw, p.jaw);
  EXPECT_EQ(back.cam_rotation, p.cam_rotation);
  EXPECT_EQ(back.cam_translation, p.cam_translation);
  EXPECT_EQ(back.sequence, 17u);
  EXPECT_EQ(back.confidence, 0.75f);
  EXPECT_FALSE(back.skin_colour.has_value());  // not measured: absent, not black
  p.skin_colour = Eigen::Vector3f(0.6f, 0.4f, 0.3f);
  ToProto(p, &m);
  ASSERT_TRUE(FromProto(m, &back));
  ASSERT_TRUE(back.skin_colour.has_value());
  EXPECT_EQ(*back.skin_colour, *p.skin_colour);
  m.add_skin_colour(1.f);  // 4 values
  std::string why;
  EXPECT_FALSE(FromProto(m, &back, &why));
  EXPECT_NE(why.find("skin_colour"), std::string::npos) << why;
  ToProto(p, &m);
  m.add_jaw(1.f);  // 4 values
  EXPECT_FALSE(FromProto(m, &back, &why));
  EXPECT_NE(why.find("jaw"), std::string::npos);
  // A frame whose skin colour is outside 0..1 is not a valid frame.
  p.skin_colour = Eigen::Vector3f(0.6f, std::nanf(""), 0.3f);
  EXPECT_FALSE(p.IsValid(&why));
  EXPECT_NE(why.find("skin colour"), std::string::npos) << why;
  // The outline: absent when not measured, kept when measured, refused when it is not one.
  p.skin_colour.reset();
  ToProto(p, &m);
  ASSERT_TRUE(FromProto(m, &back));
  EXPECT_TRUE(back.outline.empty());
  p.outline = {101.5f, 0.f, 97.25f};
  ToProto(p, &m);
  ASSERT_TRUE(FromProto(m, &back));
  EXPECT_EQ(back.outline, p.outline);
  m.set_outline(1, -3.f);
  EXPECT_FALSE(FromProto(m, &back, &why));
  EXPECT_NE(why.find("outline"), std::string::npos) << why;
}

TEST(Recording, WritesAndReadsEveryFrame) {
  const std::string path = testing::TempDir("rec") + "/a.hcrec";
  {
    RecordingWriter w(path, Info());
    for (int i = 0; i < 50; ++i) w.Write(SyntheticTalkingHead(Model(), i));
    EXPECT_EQ(w.frames_written(), 50);
  }
  RecordingInfo info;
  const std::vector<FrameParams> frames = ReadRecording(path, &info);
  ASSERT_EQ(frames.size(), 50u);
  EXPECT_EQ(info.head_model_fingerprint, Model().fingerprint());
  EXPECT_EQ(info.subject.shape, Info().subject.shape);
  EXPECT_EQ(info.subject.intrinsics.width, 256);
  for (int i = 0; i < 50; ++i) {
    const FrameParams expected = SyntheticTalkingHead(Model(), i);
    EXPECT_EQ(frames[i].expression, expected.expression);
    EXPECT_EQ(frames[i].sequence, static_cast<uint64_t>(i));
    EXPECT_DOUBLE_EQ(frames[i].capture_time_s, expected.capture_time_s);
  }
}

TEST(Recording, EveryWrittenFrameIsOnDiskBeforeWriteReturns) {
  const std::string path = testing::TempDir("flush") + "/live.hcrec";
  RecordingWriter w(path, Info());
  for (int i = 0; i < 5; ++i) w.Write(SyntheticTalkingHead(Model(), i));
  // Read while the writer is still open, as after a SIGKILL: nothing may sit in a buffer.
  std::string cut;
  EXPECT_EQ(ReadRecording(path, nullptr, &cut).size(), 5u);
  EXPECT_TRUE(cut.empty()) << cut;
}

TEST(Recording, CaptureTimesThatAreNotTimesEndTheRecording) {
  for (double bad : {std::nan(""), 1e300, -std::numeric_limits<double>::infinity()}) {
    const std::string path = testing::TempDir("times") + "/t.hcrec";
    {
      RecordingWriter w(path, Info());
      for (int i = 0; i < 6; ++i) {
        FrameParams f = SyntheticTalkingHead(Model(), i);
        if (i == 3) f.capture_time_s = bad;
        w.Write(f);
      }
    }
    std::string cut;
    EXPECT_EQ(ReadRecording(path, nullptr, &cut).size(), 3u) << bad;
    EXPECT_NE(cut.find("is not a time"), std::string::npos) << cut;
  }
}

// DIR/p.json with the first `value` after `after` replaced by `edited`, as
// DIR/bad.json: its import is refused, naming the file and `what`.
void ExpectEditRefused(const std::string& dir, const std::string& after, const std::string& value,
                       const std::string& edited, const std::string& what) {
  std::ifstream in(dir + "/p.json");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t at = text.find(value, text.find(after));
  ASSERT_NE(at, std::string::npos) << value;
  text.replace(at, value.size(), edited);
  std::ofstream(dir + "/bad.json") << text;
  try {
    ImportRecording(dir + "/bad.json");
    ADD_FAILURE() << what << " " << edited << " was taken";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

// An export and its import keep each frame's skin colour, and its absence.
TEST(RecordingExport, KeepsTheSkinColourOrItsAbsence) {
  const std::string dir = testing::TempDir("skin_export");
  LoadedRecording r;
  r.info = Info();
  for (int i = 0; i < 4; ++i) {
    r.frames.push_back(SyntheticTalkingHead(Model(), i));
    if (i % 2 == 0) r.frames.back().skin_colour = Eigen::Vector3f(0.6f + 0.01f * i, 0.45f, 0.3f);
  }
  for (const char* name : {"p.json", "p.npz"}) {
    const std::string path = dir + "/" + name;
    ExportRecording(r, ExportFormatFor("", path), path);
    const LoadedRecording back = ImportRecording(path);
    ASSERT_EQ(back.frames.size(), r.frames.size()) << name;
    for (size_t k = 0; k < r.frames.size(); ++k) {
      ASSERT_EQ(back.frames[k].skin_colour.has_value(), r.frames[k].skin_colour.has_value()) << name << " " << k;
      if (r.frames[k].skin_colour) {
        EXPECT_EQ(*back.frames[k].skin_colour, *r.frames[k].skin_colour) << name;
      }
    }
  }
  // The csv has the three columns, empty where there is none.
  ExportRecording(r, ExportFormat::kCsv, dir + "/p.csv");
  std::ifstream csv(dir + "/p.csv");
  std::string line, header, second;
  while (std::getline(csv, line) && line[0] == '#') {
  }
  header = line;
  std::getline(csv, line);
  std::getline(csv, second);
  EXPECT_NE(header.find(",skin_r,skin_g,skin_b"), std::string::npos) << header;
  const std::string skin = ",0.600000024,0.449999988,0.300000012";
  EXPECT_EQ(line.substr(line.size() - skin.size()), skin) << line;
  EXPECT_EQ(second.substr(second.size() - 3), ",,,") << second;
  // A skin colour beyond 0..1 in an edited export is refused, naming the file.
  ExpectEditRefused(dir, "\"skin_colour\": [", "0.6", "1.6", "skin colour");
}

// An export and its import keep each frame's outline, and its absence; an
// edited export with an outline beyond the codec's range is refused.
TEST(RecordingExport, KeepsTheOutlineOrItsAbsence) {
  const std::string dir = testing::TempDir("outline_export");
  LoadedRecording r;
  r.info = Info();
  for (int i = 0; i < 4; ++i) {
    r.frames.push_back(SyntheticTalkingHead(Model(), i));
    if (i != 1) r.frames.back().outline = {95.25f + i, kOutlineUnknown, 101.5f, 99.f};
  }
  for (const char* name : {"p.json", "p.npz"}) {
    const std::string path = dir + "/" + name;
    ExportRecording(r, ExportFormatFor("", path), path);
    const LoadedRecording back = ImportRecording(path);
    ASSERT_EQ(back.frames.size(), r.frames.size()) << name;
    for (size_t k = 0; k < r.frames.size(); ++k) EXPECT_EQ(back.frames[k].outline, r.frames[k].outline) << name << k;
  }
  ExportRecording(r, ExportFormat::kCsv, dir + "/p.csv");
  std::ifstream csv(dir + "/p.csv");
  std::string line, rows[2];
  while (std::getline(csv, line) && line[0] == '#') {
  }
  EXPECT_NE(line.find(",outline_0,outline_1,outline_2,outline_3"), std::string::npos) << line;
  std::getline(csv, rows[0]);
  std::getline(csv, rows[1]);
  const std::string first = ",95.25,0,101.5,99", none = ",,,,";
  EXPECT_EQ(rows[0].substr(rows[0].size() - first.size()), first) << rows[0];
  EXPECT_EQ(rows[1].substr(rows[1].size() - none.size()), none) << rows[1];
  // Frames without any outline export as before: no outline columns.
  LoadedRecording plain = r;
  for (FrameParams& f : plain.frames) f.outline.clear();
  ExportRecording(plain, ExportFormat::kJson, dir + "/plain.json");
  std::ifstream plain_in(dir + "/plain.json");
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(plain_in)), std::istreambuf_iterator<char>()).find("outline"),
            std::string::npos);
  // Outlines of different lengths cannot share the export's columns.
  LoadedRecording mixed = r;
  mixed.frames[2].outline.push_back(1.f);
  EXPECT_THROW(ExportRecording(mixed, ExportFormat::kNpz, dir + "/mixed.npz"), std::invalid_argument);
  ExpectEditRefused(dir, "\"outline\": [", "101.5", "-40.0", "outline");
}

TEST(Recording, TruncatedForeignAndMissingFiles) {
  const std::string dir = testing::TempDir("bad");
  const std::string path = dir + "/a.hcrec";
  {
    RecordingWriter w(path, Info());
    for (int i = 0; i < 20; ++i) w.Write(SyntheticTalkingHead(Model(), i));
  }
  std::filesystem::resize_file(path, std::filesystem::file_size(path) - 7);
  RecordingReader reader(path);
  FrameParams f;
  int n = 0;
  while (reader.Next(&f)) ++n;
  EXPECT_EQ(n, 19);  // every complete frame before the cut
  EXPECT_NE(reader.error().find("truncated"), std::string::npos);
  // A recorder killed mid-write leaves a replayable recording: the whole frames, and why it ends.
  std::string cut;
  EXPECT_EQ(ReadRecording(path, nullptr, &cut).size(), 19u);
  EXPECT_NE(cut.find("truncated or corrupt record"), std::string::npos) << cut;
  // Cut inside the first record: nothing to replay, an error.
  const std::string empty = dir + "/empty.hcrec";
  RecordingWriter(empty, Info()).Close();
  std::filesystem::resize_file(path, std::filesystem::file_size(empty) + 3);
  EXPECT_THROW(ReadRecording(path), std::runtime_error);
  { std::ofstream(dir + "/foreign.hcrec") << "GIF89a..."; }
  try {
    RecordingReader r(dir + "/foreign.hcrec");
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("not a headcast parameter recording"), std::string::npos);
  }
  EXPECT_THROW(RecordingReader(dir + "/none.hcrec"), std::runtime_error);
}

TEST(SyntheticMotion, IsSmoothValidAndUsesTheJaw) {
  FrameParams prev = SyntheticTalkingHead(Model(), 0);
  float max_jaw = 0;
  for (int i = 1; i < 300; ++i) {
    const FrameParams p = SyntheticTalkingHead(Model(), i);
    std::string why;
    ASSERT_TRUE(p.IsValid(&why)) << why;
    EXPECT_LT((p.cam_translation - prev.cam_translation).norm(), 0.01f);      // < 1 cm per frame
    EXPECT_LT((p.expression - prev.expression).cwiseAbs().maxCoeff(), 0.7f);  // a blink takes ~5 frames
    max_jaw = std::max(max_jaw, p.jaw.x());
    prev = p;
  }
  EXPECT_GT(max_jaw, 0.15f);
}

}  // namespace
}  // namespace headcast
