// What headcast-rec does with parameter recordings, so that researchers can
// take tracked parameters into their own tools: a summary, exports to JSON,
// CSV and npz, cutting a time range, joining recordings end to end.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "proto/recording.h"

namespace headcast {

// A recording read whole, with how it ended (a cut record, if any).
struct LoadedRecording {
  std::string path;
  RecordingInfo info;
  std::vector<FrameParams> frames;
  std::string cut;  // empty: the file ends after a whole frame
};
// Throws like ReadRecording (missing, foreign, corrupt header, no whole frame).
LoadedRecording LoadRecording(const std::string& path);

// Header, frame count, duration, frame-rate and sequence checks, and the
// range of every parameter group: what `headcast-rec info` prints.
nlohmann::json SummariseRecording(const LoadedRecording& recording);

enum class ExportFormat { kJson, kCsv, kNpz };
// "json", "csv", "npz"; throws std::invalid_argument otherwise.
ExportFormat ParseExportFormat(const std::string& name);
// The format of an export to `out_path`: `name` when given, else the path's
// extension (.json, .csv, .npz), else json. A name that contradicts one of
// those extensions is refused: the file would not be what its name says.
ExportFormat ExportFormatFor(const std::string& name, const std::string& out_path);
// Writes every frame. json: {"header": {...}, "frames": [{...}]}; csv: one
// row a frame (sequence, time, confidence, expr_0.., jaw_x.., ...), the
// header's facts in '#' lines first; npz: one array per parameter group
// (N x E expression, N x 3 rotations and translation, N times, sequences,
// confidences) plus the subject's shape, texture, light and intrinsics.
// Throws naming the file.
void ExportRecording(const LoadedRecording& recording, ExportFormat format, const std::string& out_path);

// The reverse of a json or npz export (by the file's extension): a
// recording again, value for value. Throws naming the file and the field
// for anything missing, mis-sized or not finite.
LoadedRecording ImportRecording(const std::string& path);

// Frames whose time since the first frame lies in [from_s, to_s) (to_s < 0:
// to the end). Throws std::invalid_argument for an empty or inverted range.
std::vector<FrameParams> CutByTime(const std::vector<FrameParams>& frames, double from_s, double to_s);
// Frames [first, first + count) (count < 0: to the end), checked likewise.
std::vector<FrameParams> CutByIndex(const std::vector<FrameParams>& frames, long first, long count);

// The recordings one after another: same head model (fingerprint and
// expression count) or std::invalid_argument naming the file that differs.
// Times and sequence numbers continue from the previous part (one frame
// interval apart); the header is the first one's.
LoadedRecording ConcatRecordings(const std::vector<LoadedRecording>& parts);

}  // namespace headcast
