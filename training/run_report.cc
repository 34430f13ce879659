// Progress, logs and plots.
#include "training/run_report.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

#include "common/core/image_io.h"

namespace headcast {

ProgressLine::ProgressLine(int first_step, int last_step, double file_every_s, std::string unit)
    : first_(first_step),
      last_(last_step),
      unit_(std::move(unit)),
      terminal_(isatty(fileno(stderr)) != 0),
      file_every_s_(file_every_s) {}

void ProgressLine::Show(int step, const std::string& figures) {
  const double done = (step + 1.0 - first_) / std::max(1, last_ - first_);
  const double elapsed = watch_.ElapsedSeconds();
  // The first moments (loading, warm-up) say little about the rest.
  const bool can_tell = done >= 0.01 || elapsed >= 3;
  const std::string times =
      HumanDuration(elapsed) + ", ETA " +
      (can_tell ? HumanDuration(elapsed * (1 - done) / std::max(done, 1e-9)) : std::string("estimating"));
  if (terminal_) {
    std::fprintf(stderr, "\r%s %d/%d  %s  %s   ", unit_.c_str(), step + 1, last_, figures.c_str(), times.c_str());
  } else if (step + 1 >= last_ || elapsed - last_line_s_ >= file_every_s_) {
    std::fprintf(stderr, "%s %d/%d  %s  %s\n", unit_.c_str(), step + 1, last_, figures.c_str(), times.c_str());
    last_line_s_ = elapsed;
  }
}

void ProgressLine::Finish() {
  if (terminal_) std::fprintf(stderr, "\n");
}

CsvLog::CsvLog(const std::string& path, const std::string& header, bool resume, int first_step) : path_(path) {
  std::string kept = header + "\n";
  if (resume) {
    std::ifstream in(path);
    std::string line;
    bool first = true;
    while (std::getline(in, line)) {
      if (!first && !line.empty() && std::atoi(line.c_str()) < first_step) kept += line + "\n";
      first = false;
    }
  }
  out_.open(path, std::ios::trunc);
  if (!out_) throw std::runtime_error(path + ": cannot write");
  out_ << kept << std::flush;
}

void CsvLog::Row(const std::string& row) {
  if (out_.is_open()) out_ << row << std::endl;  // flushed: a kill loses no logged row
}

std::vector<PlotSeries> ReadCsvColumns(const std::string& path, const std::vector<std::string>& columns) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot read");
  std::string line;
  std::getline(in, line);
  std::vector<std::string> header;
  for (std::stringstream ss(line); std::getline(ss, line, ',');) header.push_back(line);
  std::vector<int> index;
  std::vector<PlotSeries> out;
  for (const auto& c : columns) {
    const auto it = std::find(header.begin(), header.end(), c);
    if (it == header.end()) throw std::runtime_error(path + ": no column " + c);
    index.push_back(static_cast<int>(it - header.begin()));
    out.push_back({c, {}, {}});
  }
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    for (std::stringstream ss(line); std::getline(ss, line, ',');) cells.push_back(line);
    if (cells.empty()) continue;
    for (size_t k = 0; k < index.size(); ++k) {
      if (index[k] >= static_cast<int>(cells.size()) || cells[index[k]].empty()) continue;
      out[k].x.push_back(std::atof(cells[0].c_str()));
      out[k].y.push_back(std::atof(cells[index[k]].c_str()));
    }
  }
  return out;
}

void WritePlot(const std::string& path, const std::string& title, const std::string& x_label,
               const std::string& y_label, const std::vector<PlotSeries>& series, bool log_y) {
  const int width = 800, height = 500, left = 80, right = 20, top = 40, bottom = 60;
  cv::Mat img(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  auto ty = [&](double y) { return log_y ? std::log10(std::max(y, 1e-12)) : y; };
  for (const auto& s : series)
    for (size_t i = 0; i < s.x.size(); ++i) {
      if (!std::isfinite(s.y[i])) continue;
      x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, ty(s.y[i])), y1 = std::max(y1, ty(s.y[i]));
    }
  if (x0 > x1) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (x1 - x0 < 1e-12) x1 = x0 + 1;
  if (y1 - y0 < 1e-12) y0 -= 0.5, y1 += 0.5;
  const double pad = 0.05 * (y1 - y0);
  y0 -= pad, y1 += pad;
  auto px = [&](double x) { return left + (x - x0) / (x1 - x0) * (width - left - right); };
  auto py = [&](double y) { return height - bottom - (ty(y) - y0) / (y1 - y0) * (height - top - bottom); };
  const cv::Scalar axis(60, 60, 60), grid(225, 225, 225);
  const auto font = cv::FONT_HERSHEY_SIMPLEX;
  for (int k = 0; k <= 5; ++k) {
    const double fy = y0 + (y1 - y0) * k / 5, fx = x0 + (x1 - x0) * k / 5;
    const int yy = static_cast<int>(height - bottom - (fy - y0) / (y1 - y0) * (height - top - bottom));
    const int xx = static_cast<int>(px(fx));
    cv::line(img, {left, yy}, {width - right, yy}, grid, 1);
    cv::line(img, {xx, top}, {xx, height - bottom}, grid, 1);
    char label[32];
    std::snprintf(label, sizeof(label), "%.4g", log_y ? std::pow(10.0, fy) : fy);
    cv::putText(img, label, {4, yy + 4}, font, 0.4, axis, 1, cv::LINE_AA);
    std::snprintf(label, sizeof(label), "%.4g", fx);
    cv::putText(img, label, {xx - 15, height - bottom + 18}, font, 0.4, axis, 1, cv::LINE_AA);
  }
  cv::rectangle(img, {left, top}, {width - right, height - bottom}, axis, 1);
  cv::putText(img, title, {left, 25}, font, 0.6, axis, 1, cv::LINE_AA);
  cv::putText(img, x_label, {width / 2 - 30, height - 15}, font, 0.5, axis, 1, cv::LINE_AA);
  cv::putText(img, y_label + (log_y ? " (log)" : ""), {left + 5, top + 15}, font, 0.45, axis, 1, cv::LINE_AA);
  const cv::Scalar colours[] = {{200, 80, 30}, {30, 120, 230}, {40, 160, 40}, {160, 40, 160}, {0, 0, 0}};
  for (size_t k = 0; k < series.size(); ++k) {
    const cv::Scalar colour = colours[k % 5];
    const auto& s = series[k];
    std::vector<cv::Point> points;
    for (size_t i = 0; i < s.x.size(); ++i)
      if (std::isfinite(s.y[i])) points.emplace_back(static_cast<int>(px(s.x[i])), static_cast<int>(py(s.y[i])));
    if (points.size() == 1) cv::circle(img, points[0], 3, colour, cv::FILLED);
    if (points.size() > 1) cv::polylines(img, points, false, colour, 2, cv::LINE_AA);
    const int ly = top + 20 + 18 * static_cast<int>(k);
    cv::line(img, {width - right - 180, ly - 4}, {width - right - 155, ly - 4}, colour, 2);
    cv::putText(img, s.name, {width - right - 150, ly}, font, 0.45, axis, 1, cv::LINE_AA);
  }
  WriteImage(path, img);
}

}  // namespace headcast
