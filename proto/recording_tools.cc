// headcast-rec's operations.
#include "proto/recording_tools.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <optional>
#include <stdexcept>

#include "common/core/npy.h"
#include "common/headmodel/head_outline.h"

namespace headcast {
namespace {

// The parameter groups of a frame besides the expression, in file order.
struct Group {
  const char* name;
  Eigen::Vector3f FrameParams::*member;
};
constexpr Group kGroups[] = {{"jaw", &FrameParams::jaw},
                             {"neck", &FrameParams::neck},
                             {"left_eye", &FrameParams::left_eye},
                             {"right_eye", &FrameParams::right_eye},
                             {"cam_rotation", &FrameParams::cam_rotation},
                             {"cam_translation", &FrameParams::cam_translation}};

nlohmann::json Vec(const Eigen::VectorXf& v) { return std::vector<float>(v.data(), v.data() + v.size()); }
nlohmann::json Vec3(const Eigen::Vector3f& v) { return {v.x(), v.y(), v.z()}; }

nlohmann::json HeaderJson(const RecordingInfo& info) {
  const PinholeCamera& k = info.subject.intrinsics;
  return {{"head_model_name", info.head_model_name},
          {"head_model_fingerprint", info.head_model_fingerprint},
          {"num_expression", info.num_expression},
          {"fps", info.fps},
          {"source", info.source},
          {"subject",
           {{"shape", Vec(info.subject.shape)},
            {"texture", Vec(info.subject.texture)},
            {"light", std::vector<float>(info.subject.light.begin(), info.subject.light.end())},
            {"intrinsics", CameraToJson(k)}}}};
}

// Minimum and maximum of each coordinate of a group over all frames.
nlohmann::json Range(const std::vector<FrameParams>& frames, Eigen::Vector3f FrameParams::*m) {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max()), hi = -lo;
  for (const auto& f : frames) {
    lo = lo.cwiseMin(f.*m);
    hi = hi.cwiseMax(f.*m);
  }
  return {{"min", Vec3(lo)}, {"max", Vec3(hi)}};
}

void WriteOrThrow(std::ofstream& out, const std::string& path) {
  out.flush();
  if (!out) throw std::runtime_error(path + ": cannot write");
}

// The outline's arcs in a recording's frames: 0 when none carries one; the
// frames that do all carry as many (one sender's), or the export is refused.
int OutlineBins(const std::vector<FrameParams>& frames) {
  size_t bins = 0;
  for (const FrameParams& f : frames) {
    if (f.outline.empty()) continue;
    if (bins != 0 && f.outline.size() != bins)
      throw std::invalid_argument("the frames' outlines have different numbers of arcs (" + std::to_string(bins) +
                                  " and " + std::to_string(f.outline.size()) + ")");
    bins = f.outline.size();
  }
  return static_cast<int>(bins);
}

}  // namespace

LoadedRecording LoadRecording(const std::string& path) {
  LoadedRecording r;
  r.path = path;
  r.frames = ReadRecording(path, &r.info, &r.cut);
  return r;
}

nlohmann::json SummariseRecording(const LoadedRecording& r) {
  const auto& f = r.frames;
  const double duration = f.empty() ? 0 : f.back().capture_time_s - f.front().capture_time_s;
  int gaps = 0, backwards = 0;
  for (size_t i = 1; i < f.size(); ++i) {
    if (f[i].sequence > f[i - 1].sequence + 1) ++gaps;
    if (f[i].capture_time_s < f[i - 1].capture_time_s) ++backwards;
  }
  // Expression: how much each component moves, to see which ones a track uses.
  const int e = r.info.num_expression;
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(e), sum2 = Eigen::VectorXd::Zero(e);
  double min_conf = 1;
  for (const auto& fr : f) {
    const Eigen::VectorXd x = fr.expression.cast<double>().head(std::min<int>(e, fr.expression.size()));
    sum.head(x.size()) += x;
    sum2.head(x.size()) += x.cwiseAbs2();
    min_conf = std::min<double>(min_conf, fr.confidence);
  }
  const double n = static_cast<double>(std::max<size_t>(f.size(), 1));
  const Eigen::VectorXd sd = (sum2 / n - (sum / n).cwiseAbs2()).cwiseMax(0).cwiseSqrt();
  int moving = 0;
  for (int i = 0; i < e; ++i) moving += sd[i] > 0.01;
  nlohmann::json s = HeaderJson(r.info);
  s.erase("subject");
  s["file"] = r.path;
  s["frames"] = f.size();
  s["duration_s"] = duration;
  s["measured_fps"] = duration > 0 ? (static_cast<double>(f.size()) - 1) / duration : 0.0;
  s["first_sequence"] = f.empty() ? 0 : f.front().sequence;
  s["last_sequence"] = f.empty() ? 0 : f.back().sequence;
  s["sequence_gaps"] = gaps;
  s["times_going_back"] = backwards;
  s["min_confidence"] = min_conf;
  s["expression_sd"] = std::vector<double>(sd.data(), sd.data() + sd.size());
  s["expression_components_moving"] = moving;  // sd above 0.01
  for (const Group& g : kGroups) s["range"][g.name] = Range(f, g.member);
  s["complete"] = r.cut.empty();
  if (!r.cut.empty()) s["cut"] = r.cut;
  return s;
}

ExportFormat ParseExportFormat(const std::string& name) {
  if (name == "json") return ExportFormat::kJson;
  if (name == "csv") return ExportFormat::kCsv;
  if (name == "npz") return ExportFormat::kNpz;
  throw std::invalid_argument("--format wants json, csv or npz (got '" + name + "')");
}

ExportFormat ExportFormatFor(const std::string& name, const std::string& out_path) {
  std::string extension = std::filesystem::path(out_path).extension().string();
  if (!extension.empty()) extension.erase(0, 1);
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  const bool known = extension == "json" || extension == "csv" || extension == "npz";
  if (name.empty()) return ParseExportFormat(known ? extension : "json");
  const ExportFormat format = ParseExportFormat(name);
  if (known && extension != name)
    throw std::invalid_argument("--format " + name + " into " + out_path + ": the file would not be the " + extension +
                                " its name says (drop --format, or name the file ." + name + ")");
  return format;
}

void ExportRecording(const LoadedRecording& r, ExportFormat format, const std::string& out_path) {
  const int e = r.info.num_expression;
  const int outline_bins = OutlineBins(r.frames);
  const size_t n = r.frames.size();
  auto expression_of = [&](const FrameParams& f, int i) { return i < f.expression.size() ? f.expression[i] : 0.f; };
  if (format == ExportFormat::kNpz) {
    NpzArchive npz;
    std::vector<float> expr(n * e);
    std::vector<double> times(n);
    std::vector<int64_t> sequence(n);
    std::vector<float> confidence(n);
    for (size_t k = 0; k < n; ++k) {
      for (int i = 0; i < e; ++i) expr[k * e + i] = expression_of(r.frames[k], i);
      times[k] = r.frames[k].capture_time_s;
      sequence[k] = static_cast<int64_t>(r.frames[k].sequence);
      confidence[k] = r.frames[k].confidence;
    }
    const int64_t rows = static_cast<int64_t>(n);
    npz["expression"] = NpyArray::From<float>({rows, e}, expr.data());
    for (const Group& g : kGroups) {
      std::vector<float> v(n * 3);
      for (size_t k = 0; k < n; ++k)
        for (int i = 0; i < 3; ++i) v[k * 3 + i] = (r.frames[k].*g.member)[i];
      npz[g.name] = NpyArray::From<float>({rows, 3}, v.data());
    }
    npz["capture_time_s"] = NpyArray::From<double>({rows}, times.data());
    npz["sequence"] = NpyArray::From<int64_t>({rows}, sequence.data());
    npz["confidence"] = NpyArray::From<float>({rows}, confidence.data());
    // The face's measured skin colour (RGB, 0..1); NaN where a frame has none.
    std::vector<float> skin(n * 3, std::numeric_limits<float>::quiet_NaN());
    for (size_t k = 0; k < n; ++k)
      if (r.frames[k].skin_colour)
        for (int i = 0; i < 3; ++i) skin[k * 3 + i] = (*r.frames[k].skin_colour)[i];
    npz["skin_colour"] = NpyArray::From<float>({rows, 3}, skin.data());
    // The top of the head's outline (FrameParams::outline): NaN rows where a frame has none.
    if (outline_bins > 0) {
      std::vector<float> outline(n * outline_bins, std::numeric_limits<float>::quiet_NaN());
      for (size_t k = 0; k < n; ++k)
        std::copy(r.frames[k].outline.begin(), r.frames[k].outline.end(), outline.begin() + k * outline_bins);
      npz["outline"] = NpyArray::From<float>({rows, outline_bins}, outline.data());
    }
    const SubjectParams& s = r.info.subject;
    npz["shape"] = NpyArray::From<float>({static_cast<int64_t>(s.shape.size())}, s.shape.data());
    npz["texture"] = NpyArray::From<float>({static_cast<int64_t>(s.texture.size())}, s.texture.data());
    npz["light"] = NpyArray::From<float>({27}, s.light.data());
    const double k[6] = {s.intrinsics.fx,
                         s.intrinsics.fy,
                         s.intrinsics.cx,
                         s.intrinsics.cy,
                         static_cast<double>(s.intrinsics.width),
                         static_cast<double>(s.intrinsics.height)};
    npz["intrinsics"] = NpyArray::From<double>({6}, k);  // fx, fy, cx, cy, width, height
    npz["header_json"] = StringsToNpy({HeaderJson(r.info).dump()});
    WriteNpz(out_path, npz);
    return;
  }
  std::ofstream out(out_path);
  if (!out) throw std::runtime_error(out_path + ": cannot write");
  if (format == ExportFormat::kJson) {
    nlohmann::json frames = nlohmann::json::array();
    for (const auto& f : r.frames) {
      nlohmann::json j = {{"sequence", f.sequence},
                          {"capture_time_s", f.capture_time_s},
                          {"confidence", f.confidence},
                          {"expression", Vec(f.expression)}};
      for (const Group& g : kGroups) j[g.name] = Vec3(f.*g.member);
      j["skin_colour"] = f.skin_colour ? nlohmann::json(Vec3(*f.skin_colour)) : nlohmann::json(nullptr);
      if (outline_bins > 0) j["outline"] = f.outline.empty() ? nlohmann::json(nullptr) : nlohmann::json(f.outline);
      frames.push_back(std::move(j));
    }
    out << nlohmann::json({{"header", HeaderJson(r.info)}, {"frames", frames}}).dump(1) << "\n";
  } else {
    out << "# headcast parameter recording: " << r.info.head_model_name << " (" << r.info.head_model_fingerprint
        << "), " << e << " expression components, " << r.info.fps << " fps, source: " << r.info.source << "\n";
    out << "# rotations are axis-angle (radians), cam_* is cam_from_head, translation in metres\n";
    out << "sequence,capture_time_s,confidence";
    for (int i = 0; i < e; ++i) out << ",expr_" << i;
    for (const Group& g : kGroups)
      for (const char* axis : {"x", "y", "z"}) out << "," << g.name << "_" << axis;
    out << ",skin_r,skin_g,skin_b";  // empty where the frame has no measured skin colour
    for (int i = 0; i < outline_bins; ++i) out << ",outline_" << i;  // mm; empty where the frame has none
    out << "\n" << std::setprecision(9);
    for (const auto& f : r.frames) {
      out << f.sequence << "," << std::setprecision(15) << f.capture_time_s << std::setprecision(9) << ","
          << f.confidence;
      for (int i = 0; i < e; ++i) out << "," << expression_of(f, i);
      for (const Group& g : kGroups)
        for (int i = 0; i < 3; ++i) out << "," << (f.*g.member)[i];
      for (int i = 0; i < 3; ++i) {
        out << ",";
        if (f.skin_colour) out << (*f.skin_colour)[i];
      }
      for (int i = 0; i < outline_bins; ++i) {
        out << ",";
        if (!f.outline.empty()) out << f.outline[i];
      }
      out << "\n";
    }
  }
  WriteOrThrow(out, out_path);
}

namespace {

RecordingInfo HeaderFromJson(const nlohmann::json& h) {
  RecordingInfo info;
  info.head_model_name = h.at("head_model_name").get<std::string>();
  info.head_model_fingerprint = h.at("head_model_fingerprint").get<std::string>();
  info.num_expression = h.at("num_expression").get<int>();
  info.fps = h.at("fps").get<double>();
  info.source = h.at("source").get<std::string>();
  if (info.num_expression < 0 || info.num_expression > 4096 || !(info.fps > 0 && info.fps < 1e4))
    throw std::invalid_argument("num_expression or fps out of range");
  const nlohmann::json& s = h.at("subject");
  const auto shape = s.at("shape").get<std::vector<float>>(), texture = s.at("texture").get<std::vector<float>>();
  const auto light = s.at("light").get<std::vector<float>>();
  if (light.size() != 27) throw std::invalid_argument("subject.light must have 27 values");
  info.subject.shape = Eigen::Map<const Eigen::VectorXf>(shape.data(), static_cast<Eigen::Index>(shape.size()));
  info.subject.texture = Eigen::Map<const Eigen::VectorXf>(texture.data(), static_cast<Eigen::Index>(texture.size()));
  std::copy(light.begin(), light.end(), info.subject.light.begin());
  info.subject.intrinsics = CameraFromJson(s.at("intrinsics"));
  return info;
}

Eigen::Vector3f Vec3From(const nlohmann::json& j, const char* name) {
  const auto v = j.at(name).get<std::vector<float>>();
  if (v.size() != 3) throw std::invalid_argument(std::string(name) + " must have 3 values");
  return {v[0], v[1], v[2]};
}

// A frame's skin colour from an npz row: none when all three are NaN (not measured).
std::optional<Eigen::Vector3f> SkinColourFrom(const float* rgb) {
  const Eigen::Vector3f v(rgb[0], rgb[1], rgb[2]);
  if (v.array().isNaN().all()) return std::nullopt;
  return v;
}

template <typename T>
const T* Column(const NpzArchive& npz, const std::string& name, std::vector<int64_t> shape) {
  const auto it = npz.find(name);
  if (it == npz.end()) throw std::invalid_argument("no array '" + name + "'");
  if (it->second.shape() != shape) throw std::invalid_argument("array '" + name + "' has another shape");
  return it->second.data<T>();
}

}  // namespace

LoadedRecording ImportRecording(const std::string& path) {
  LoadedRecording r;
  r.path = path;
  const bool npz = path.size() > 4 && path.compare(path.size() - 4, 4, ".npz") == 0;
  try {
    if (npz) {
      const NpzArchive a = ReadNpz(path);
      const auto header = a.find("header_json");
      if (header == a.end()) throw std::invalid_argument("no array 'header_json' (not a headcast-rec export)");
      const std::vector<std::string> text = NpyToStrings(header->second);
      if (text.size() != 1) throw std::invalid_argument("header_json must hold one text");
      r.info = HeaderFromJson(nlohmann::json::parse(text[0]));
      const auto times_it = a.find("capture_time_s");
      if (times_it == a.end() || times_it->second.shape().size() != 1)
        throw std::invalid_argument("no one-dimensional array 'capture_time_s'");
      const int64_t n = times_it->second.shape()[0], e = r.info.num_expression;
      const double* times = Column<double>(a, "capture_time_s", {n});
      const int64_t* sequence = Column<int64_t>(a, "sequence", {n});
      const float* confidence = Column<float>(a, "confidence", {n});
      const float* expression = Column<float>(a, "expression", {n, e});
      r.frames.resize(static_cast<size_t>(n));
      for (const Group& g : kGroups) {
        const float* v = Column<float>(a, g.name, {n, 3});
        for (int64_t k = 0; k < n; ++k) r.frames[k].*g.member = Eigen::Vector3f(v[3 * k], v[3 * k + 1], v[3 * k + 2]);
      }
      // Exports from before the skin colour was kept have no such array.
      const float* skin = a.count("skin_colour") ? Column<float>(a, "skin_colour", {n, 3}) : nullptr;
      // Exports of frames without an outline, or from before it was kept, have no such array.
      const auto outline_it = a.find("outline");
      int64_t bins = 0;
      if (outline_it != a.end()) {
        const std::vector<int64_t>& shape = outline_it->second.shape();
        if (shape.size() != 2 || shape[0] != n || shape[1] < 1 || shape[1] > kMaxOutlineBins)
          throw std::invalid_argument("array 'outline' must have one row a frame and 1 to " +
                                      std::to_string(kMaxOutlineBins) + " arcs");
        bins = shape[1];
      }
      const float* outline = bins > 0 ? Column<float>(a, "outline", {n, bins}) : nullptr;
      for (int64_t k = 0; k < n; ++k) {
        FrameParams& f = r.frames[k];
        if (skin) f.skin_colour = SkinColourFrom(skin + 3 * k);
        if (outline && !std::isnan(outline[k * bins])) f.outline.assign(outline + k * bins, outline + (k + 1) * bins);
        f.expression = Eigen::Map<const Eigen::VectorXf>(expression + k * e, e);
        f.capture_time_s = times[k];
        if (sequence[k] < 0) throw std::invalid_argument("a negative sequence number");
        f.sequence = static_cast<uint64_t>(sequence[k]);
        f.confidence = confidence[k];
      }
    } else {
      std::ifstream in(path);
      if (!in) throw std::runtime_error("cannot open");
      const nlohmann::json j = nlohmann::json::parse(in);
      r.info = HeaderFromJson(j.at("header"));
      for (const auto& fj : j.at("frames")) {
        FrameParams f;
        const auto expr = fj.at("expression").get<std::vector<float>>();
        if (static_cast<int>(expr.size()) != r.info.num_expression)
          throw std::invalid_argument("frame " + std::to_string(r.frames.size()) + ": " + std::to_string(expr.size()) +
                                      " expression values, the header says " + std::to_string(r.info.num_expression));
        f.expression = Eigen::Map<const Eigen::VectorXf>(expr.data(), static_cast<Eigen::Index>(expr.size()));
        for (const Group& g : kGroups) f.*g.member = Vec3From(fj, g.name);
        f.capture_time_s = fj.at("capture_time_s").get<double>();
        f.sequence = fj.at("sequence").get<uint64_t>();
        f.confidence = fj.at("confidence").get<float>();
        // Null: not measured; absent: an export from before the skin colour was kept.
        if (fj.contains("skin_colour") && !fj.at("skin_colour").is_null()) f.skin_colour = Vec3From(fj, "skin_colour");
        if (fj.contains("outline") && !fj.at("outline").is_null())
          f.outline = fj.at("outline").get<std::vector<float>>();
        r.frames.push_back(std::move(f));
      }
    }
    for (size_t k = 0; k < r.frames.size(); ++k) {
      const FrameParams& f = r.frames[k];
      bool finite = std::isfinite(f.capture_time_s) && std::isfinite(f.confidence) && f.expression.allFinite();
      for (const Group& g : kGroups) finite = finite && (f.*g.member).allFinite();
      if (!finite) throw std::invalid_argument("frame " + std::to_string(k) + " has a value that is not finite");
      if (f.skin_colour &&
          !(f.skin_colour->allFinite() && f.skin_colour->minCoeff() >= 0 && f.skin_colour->maxCoeff() <= 1))
        throw std::invalid_argument("frame " + std::to_string(k) + ": a skin colour that is not three numbers in 0..1");
      if (std::string why; !OutlineIsValid(f.outline, &why))
        throw std::invalid_argument("frame " + std::to_string(k) + ": " + why);
    }
    if (r.frames.empty()) throw std::invalid_argument("no frames");
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot import: " + e.what());
  }
  return r;
}

std::vector<FrameParams> CutByTime(const std::vector<FrameParams>& frames, double from_s, double to_s) {
  if (!std::isfinite(from_s) || from_s < 0 || !std::isfinite(to_s) || (to_s >= 0 && to_s <= from_s))
    throw std::invalid_argument("the time range must satisfy 0 <= from < to (seconds from the first frame)");
  std::vector<FrameParams> out;
  if (frames.empty()) return out;
  const double t0 = frames.front().capture_time_s;
  for (const auto& f : frames) {
    const double t = f.capture_time_s - t0;
    if (t >= from_s - 1e-9 && (to_s < 0 || t < to_s - 1e-9)) out.push_back(f);
  }
  if (out.empty()) throw std::invalid_argument("no frame lies in that time range");
  return out;
}

std::vector<FrameParams> CutByIndex(const std::vector<FrameParams>& frames, long first, long count) {
  const long n = static_cast<long>(frames.size());
  if (first < 0 || first >= n || count == 0)
    throw std::invalid_argument("frames from " + std::to_string(first) + " (count " + std::to_string(count) +
                                "): the recording has frames 0.." + std::to_string(n - 1));
  const long last = count < 0 ? n : std::min(n, first + count);
  return std::vector<FrameParams>(frames.begin() + first, frames.begin() + last);
}

LoadedRecording ConcatRecordings(const std::vector<LoadedRecording>& parts) {
  if (parts.empty()) throw std::invalid_argument("nothing to join");
  LoadedRecording out;
  out.info = parts.front().info;
  out.path = "joined";
  const double interval = 1.0 / std::max(out.info.fps, 1e-3);
  for (const auto& p : parts) {
    if (p.info.head_model_fingerprint != out.info.head_model_fingerprint ||
        p.info.num_expression != out.info.num_expression)
      throw std::invalid_argument(p.path + ": recorded with head model '" + p.info.head_model_name + "' (" +
                                  p.info.head_model_fingerprint + ", " + std::to_string(p.info.num_expression) +
                                  " expressions), the first part with '" + out.info.head_model_name + "' (" +
                                  out.info.head_model_fingerprint + ", " + std::to_string(out.info.num_expression) +
                                  ")");
    if (p.frames.empty()) continue;
    // This part's times and sequence numbers continue one frame after the previous part's last.
    const double shift =
        out.frames.empty() ? 0 : out.frames.back().capture_time_s + interval - p.frames.front().capture_time_s;
    const uint64_t seq0 = out.frames.empty() ? p.frames.front().sequence : out.frames.back().sequence + 1;
    for (const auto& f : p.frames) {
      FrameParams g = f;
      g.capture_time_s += shift;
      const uint64_t first = p.frames.front().sequence;
      g.sequence = seq0 + (f.sequence >= first ? f.sequence - first : static_cast<uint64_t>(&f - p.frames.data()));
      out.frames.push_back(std::move(g));
    }
  }
  return out;
}

}  // namespace headcast
