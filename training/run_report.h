// What a long training step leaves behind for people: a progress line with
// ETA, CSV logs that survive a kill (flushed per row, redone rows dropped on
// resume) and PNG line plots.
#pragma once

#include <fstream>
#include <string>
#include <vector>

#include "common/core/timer.h"

namespace headcast {

// "step 120/1000  loss 0.0123  35 s, ETA 4.3 min" on stderr: redrawn in place
// on a terminal; in a file (a log), a whole line every `file_every_s` and at
// the last step, so logs hold lines rather than carriage returns.
class ProgressLine {
 public:
  // `unit` names what is counted ("step", "frame").
  ProgressLine(int first_step, int last_step, double file_every_s = 30, std::string unit = "step");
  void Show(int step, const std::string& figures);
  void Finish();

 private:
  int first_, last_;
  std::string unit_;
  bool terminal_;
  double file_every_s_, last_line_s_ = -1e9;
  Stopwatch watch_;
};

// A CSV with a header row whose first column is the step. Opened for a resumed
// run, it keeps the rows before `first_step` and drops the rest (the
// interrupted run's steps after its last checkpoint are redone).
class CsvLog {
 public:
  CsvLog() = default;
  CsvLog(const std::string& path, const std::string& header, bool resume, int first_step);
  bool is_open() const { return out_.is_open(); }
  void Row(const std::string& row);  // "step,..." without the newline; flushed
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::ofstream out_;
};

struct PlotSeries {
  std::string name;
  std::vector<double> x, y;
};

// A line plot (axes, ticks, legend) as a PNG; `log_y` for losses.
void WritePlot(const std::string& path, const std::string& title, const std::string& x_label,
               const std::string& y_label, const std::vector<PlotSeries>& series, bool log_y = false);

// The columns of a CSV written by CsvLog (or any numeric CSV with a header).
std::vector<PlotSeries> ReadCsvColumns(const std::string& path, const std::vector<std::string>& columns);

}  // namespace headcast
