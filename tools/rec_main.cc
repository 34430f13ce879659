// headcast-rec: parameter recordings (.hcrec) for other tools — summary,
// exports to JSON, CSV and npz and back, cutting and joining.
#include <CLI/CLI.hpp>
#include <iostream>

#include "common/core/log.h"
#include "common/core/program.h"
#include "common/core/version.h"
#include "proto/recording_tools.h"

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-rec: inspect, export, cut and join parameter recordings (.hcrec)"};
  headcast::AddVersionFlag(app);
  headcast::AddConfigFile(app);
  app.fallthrough();  // global flags (--log, --config) after a subcommand too
  app.require_subcommand(1);
  std::string log_level;
  app.add_option("--log", log_level, "log level: trace, debug, info, warn, error");

  std::string in, out, format;
  auto* info = app.add_subcommand("info", "header, frames, duration, gaps and parameter ranges, as JSON");
  info->add_option("recording", in, ".hcrec file")->required();

  auto* exp = app.add_subcommand("export", "every frame to JSON, CSV or npz (numpy.load)");
  exp->add_option("recording", in, ".hcrec file")->required();
  exp->add_option("--format", format, "json, csv or npz (default: the --out file's extension, else json)");
  exp->add_option("--out", out, "output file")->required();

  auto* imp = app.add_subcommand("import", "a json or npz export back to a recording, value for value");
  imp->add_option("export", in, "file written by export (json or npz)")->required();
  imp->add_option("--out", out, "output .hcrec")->required();

  double from_s = 0, to_s = -1;
  long first = -1, count = -1;
  auto* cut = app.add_subcommand("cut", "a part of a recording: a time range or a frame range");
  cut->add_option("recording", in, ".hcrec file")->required();
  cut->add_option("--from", from_s, "start, seconds after the first frame")->capture_default_str();
  cut->add_option("--to", to_s, "end (exclusive), seconds after the first frame; default: the end");
  cut->add_option("--first-frame", first, "or: the first frame's index (0-based)");
  cut->add_option("--frames", count, "with --first-frame: how many frames (default: to the end)");
  cut->add_option("--out", out, "output .hcrec")->required();

  std::vector<std::string> parts;
  auto* concat = app.add_subcommand("concat", "recordings of one head model one after another");
  concat->add_option("recordings", parts, "two or more .hcrec files, in order")->required()->expected(2, -1);
  concat->add_option("--out", out, "output .hcrec")->required();

  return RunProgram(app, argc, argv, [&] {
    InitLogging(log_level);
    if (info->parsed()) {
      std::cout << SummariseRecording(LoadRecording(in)).dump(2) << "\n";
    } else if (exp->parsed()) {
      const LoadedRecording r = LoadRecording(in);
      const ExportFormat f = ExportFormatFor(format, out);
      ExportRecording(r, f, out);
      spdlog::info("wrote {} ({} frames, {})", out, r.frames.size(),
                   f == ExportFormat::kNpz   ? "npz"
                   : f == ExportFormat::kCsv ? "csv"
                                             : "json");
    } else if (imp->parsed()) {
      const LoadedRecording r = ImportRecording(in);
      WriteRecording(out, r.info, r.frames);
      spdlog::info("wrote {} ({} frames)", out, r.frames.size());
    } else if (cut->parsed()) {
      const LoadedRecording r = LoadRecording(in);
      const std::vector<FrameParams> frames =
          first >= 0 ? CutByIndex(r.frames, first, count) : CutByTime(r.frames, from_s, to_s);
      WriteRecording(out, r.info, frames);
      spdlog::info("wrote {} ({} of {} frames)", out, frames.size(), r.frames.size());
    } else if (concat->parsed()) {
      std::vector<LoadedRecording> loaded;
      for (const auto& p : parts) loaded.push_back(LoadRecording(p));
      const LoadedRecording joined = ConcatRecordings(loaded);
      WriteRecording(out, joined.info, joined.frames);
      spdlog::info("wrote {} ({} frames from {} recordings)", out, joined.frames.size(), loaded.size());
    }
    return 0;
  });
}
