// headcast-headmodel: convert head-model sources, summarise a model, render previews.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <opencv2/core/persistence.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/core/image_io.h"
#include "common/core/log.h"
#include "common/core/program.h"
#include "common/core/version.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_model_io.h"
#include "common/headmodel/head_render.h"
#include "common/headmodel/ict_converter.h"
#include "common/headmodel/mesh_io.h"
#include "common/headmodel/synthetic_motion.h"

namespace headcast {
namespace {

struct RenderArgs {
  std::string model = "builtin";
  std::string out;
  std::string video;
  std::string sweep;  // "", expression, jaw, turn, all
  std::string view = "front";
  int size = 512;
  double yaw = 0, pitch = 0, jaw_deg = 0;
  std::vector<std::string> expressions;  // name=value
  std::vector<std::string> shapes;       // index=value
  bool landmarks = false;
};

// Framing that fits the face for any model: centred on the landmarks.
struct Framing {
  PinholeCamera camera;
  double distance;
  Eigen::Vector3d target;
};

Framing FrameModel(const HeadModel& model, int size) {
  const HeadModelOutput rest = model.Forward(HeadModelParams{});
  const Eigen::RowVector3f centre = rest.landmarks.colwise().mean();
  const float extent = rest.landmarks.col(1).maxCoeff() - rest.landmarks.col(1).minCoeff();
  Framing f;
  const double fov = 24.0;
  f.camera = PinholeCamera::FromFovY(size, size, fov);
  f.target = centre.cast<double>().transpose() + Eigen::Vector3d(0, -0.1 * extent, 0);
  f.distance = 2.0 * extent / (2 * std::tan(0.5 * fov * M_PI / 180));
  return f;
}

cv::Mat RenderOne(const HeadModel& model, const HeadModelParams& params, const Framing& framing, double yaw,
                  double pitch, const cv::Mat& albedo, bool landmarks) {
  const HeadModelOutput out = model.Forward(params);
  const RigidTransform cam_from_head = FrontalCamFromHead(framing.distance, yaw, pitch, framing.target);
  HeadRender r = RenderHead(model, out.vertices, cam_from_head, framing.camera, albedo);
  if (landmarks) {
    std::vector<Eigen::Vector2d> pts;
    for (int l = 0; l < kNumLandmarks; ++l)
      pts.push_back(framing.camera.Project(cam_from_head.Apply(out.landmarks.row(l).transpose().cast<double>())));
    DrawPoints(&r.image_bgr, pts, cv::Scalar(60, 255, 60), std::max(1, framing.camera.width / 256));
  }
  return r.image_bgr;
}

void Label(cv::Mat* image, const std::string& text) {
  const double scale = image->cols / 512.0 * 0.6;
  cv::putText(*image, text, {8, static_cast<int>(24 * scale / 0.6)}, cv::FONT_HERSHEY_SIMPLEX, scale,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
}

HeadModelParams ParamsFromArgs(const HeadModel& model, const RenderArgs& args) {
  HeadModelParams p;
  p.shape = Eigen::VectorXd::Zero(model.num_shape());
  p.expression = Eigen::VectorXd::Zero(model.num_expression());
  p.pose[3 * kJawJoint] = args.jaw_deg * M_PI / 180;
  for (const auto& e : args.expressions) {
    const auto eq = e.find('=');
    if (eq == std::string::npos) throw std::invalid_argument("--expression wants name=value, got '" + e + "'");
    const std::string name = e.substr(0, eq);
    const int idx = model.ExpressionIndex(name);
    if (idx < 0)
      throw std::invalid_argument("model has no expression component '" + name + "' (see: headcast-headmodel summary)");
    p.expression[idx] = ParseNumber<float>(e.substr(eq + 1), "--expression " + name);
  }
  for (const auto& e : args.shapes) {
    const auto eq = e.find('=');
    if (eq == std::string::npos) throw std::invalid_argument("--shape wants index=value, got '" + e + "'");
    const int idx = ParseNumber<int>(e.substr(0, eq), "--shape (an index)");
    if (idx < 0 || idx >= model.num_shape())
      throw std::invalid_argument("--shape: the model has shape components 0.." +
                                  std::to_string(model.num_shape() - 1));
    p.shape[idx] = ParseNumber<float>(e.substr(eq + 1), "--shape " + std::to_string(idx));
  }
  return p;
}

struct RgbdRenderOptions {
  int frames = 30, width = 640;
  int first_frame = 0;  // of the synthetic motion: a later part of the same sequence
  double fov_deg = 45, noise_mm = 0;
  double stereo_baseline_m = 0;  // > 0: also side-by-side stereo frames and their calibration
};

// The calibration of the rendered stereo pair (OpenCV YAML, as
// ReadStereoCalibration reads it): one camera, the right one `baseline` to the
// right, no distortion, no rotation.
void WriteStereoCalibration(const std::string& path, const PinholeCamera& camera, double baseline) {
  cv::FileStorage fs(path, cv::FileStorage::WRITE);
  if (!fs.isOpened()) throw std::runtime_error(path + ": cannot write");
  const cv::Mat K = (cv::Mat_<double>(3, 3) << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1);
  fs << "image_width" << camera.width << "image_height" << camera.height;
  fs << "K1" << K << "D1" << cv::Mat::zeros(1, 5, CV_64F) << "K2" << K << "D2" << cv::Mat::zeros(1, 5, CV_64F);
  fs << "R" << cv::Mat::eye(3, 3, CV_64F) << "T" << (cv::Mat_<double>(3, 1) << -baseline, 0, 0);
}

// A synthetic RGB-D sequence of the talking head (known parameters): colour
// and 16-bit millimetre depth PNGs with a TUM-style associations.txt, and the
// truth (parameters, camera) as JSON — for testing RGB-D tracking end to end.
// With a stereo baseline also side-by-side frames (left | right, as a
// ZED-style camera delivers them) and stereo.yml, for the stereo path.
int RenderRgbd(const RenderArgs& args, const RgbdRenderOptions& o) {
  const int frames = o.frames, width = o.width, height = o.width * 3 / 4;
  const double fov = o.fov_deg, noise_mm = o.noise_mm;
  const HeadModel model = LoadHeadModelSpec(args.model);
  const HeadModelParams base = ParamsFromArgs(model, args);
  const HeadIdentity id = model.MakeIdentity(base.shape);
  const cv::Mat albedo = AlbedoTexture(model);
  const PinholeCamera camera = PinholeCamera::FromFovY(width, height, fov);
  std::filesystem::create_directories(args.out + "/rgb");
  std::filesystem::create_directories(args.out + "/depth");
  if (o.stereo_baseline_m > 0) {
    std::filesystem::create_directories(args.out + "/side_by_side");
    WriteStereoCalibration(args.out + "/stereo.yml", camera, o.stereo_baseline_m);
  }
  std::ofstream assoc(args.out + "/associations.txt");
  assoc << "# headcast-headmodel render-rgbd: time rgb time depth (depth: uint16 millimetres, 0 unknown)\n";
  std::ofstream truth(args.out + "/truth.json");
  truth.precision(9);
  truth << "{\"camera\": {\"fx\": " << camera.fx << ", \"fy\": " << camera.fy << ", \"cx\": " << camera.cx
        << ", \"cy\": " << camera.cy << "},\n \"shape\": [";
  for (int k = 0; k < model.num_shape(); ++k) truth << (k ? ", " : "") << base.shape[k];
  truth << "],\n \"frames\": [";
  cv::RNG rng(7);
  SyntheticMotionOptions motion;
  motion.distance = 0.55;
  for (int i = 0; i < frames; ++i) {
    const FrameParams f = SyntheticTalkingHead(model, o.first_frame + i, motion);
    HeadModelOutput out;
    model.Forward(id, f.expression.cast<double>(), f.HeadPose(), &out);
    const HeadRender r = RenderHead(model, out.vertices, f.CamFromHead(), camera, albedo);
    cv::Mat depth_mm(r.depth.size(), CV_16UC1, cv::Scalar(0));
    cv::Mat noise(r.depth.size(), CV_32F, cv::Scalar(0));
    if (noise_mm > 0) rng.fill(noise, cv::RNG::NORMAL, 0, noise_mm);
    for (int y = 0; y < depth_mm.rows; ++y)
      for (int x = 0; x < depth_mm.cols; ++x) {
        // The wall behind the head is 1.4 m away.
        const float z = r.mask.at<uchar>(y, x) ? r.depth.at<float>(y, x) * 1000.f : 1400.f;
        depth_mm.at<uint16_t>(y, x) = cv::saturate_cast<uint16_t>(z + noise.at<float>(y, x));
      }
    char name[32];
    std::snprintf(name, sizeof(name), "%05d.png", i);
    WriteImage(args.out + "/rgb/" + name, r.image_bgr);
    cv::imwrite(args.out + "/depth/" + name, depth_mm);
    if (o.stereo_baseline_m > 0) {
      RigidTransform right_from_head = f.CamFromHead();
      right_from_head.translation.x() -= o.stereo_baseline_m;
      const HeadRender right = RenderHead(model, out.vertices, right_from_head, camera, albedo);
      cv::Mat both;
      cv::hconcat(r.image_bgr, right.image_bgr, both);
      WriteImage(args.out + "/side_by_side/" + name, both);
    }
    const double t = i / motion.fps;
    assoc << t << " rgb/" << name << " " << t << " depth/" << name << "\n";
    truth << (i ? ",\n  " : "\n  ") << "{\"jaw\": [" << f.jaw.x() << ", " << f.jaw.y() << ", " << f.jaw.z()
          << "], \"cam_rotation\": [" << f.cam_rotation.x() << ", " << f.cam_rotation.y() << ", " << f.cam_rotation.z()
          << "], \"cam_translation\": [" << f.cam_translation.x() << ", " << f.cam_translation.y() << ", "
          << f.cam_translation.z() << "]}";
  }
  truth << "]}\n";
  std::cout << "wrote " << frames << " RGB-D frames to " << args.out << " (camera fx " << camera.fx << ")\n";
  return 0;
}

// The posed mesh as OBJ/PLY and, optionally, its 68 landmarks as JSON
// {"index": [x, y, z]} (the format headcast-fit-mesh --landmarks reads).
int Export(const RenderArgs& args, const std::string& landmarks_out) {
  const HeadModel model = LoadHeadModelSpec(args.model);
  const HeadModelOutput out = model.Forward(ParamsFromArgs(model, args));
  WriteMesh(args.out, TriangleMesh{out.vertices, model.data().faces});
  if (!landmarks_out.empty()) {
    std::ofstream f(landmarks_out);
    f.precision(9);
    f << "{";
    for (int l = 0; l < kNumLandmarks; ++l)
      f << (l ? ",\n " : "") << '"' << l << "\": [" << out.landmarks(l, 0) << ", " << out.landmarks(l, 1) << ", "
        << out.landmarks(l, 2) << "]";
    f << "}\n";
    if (!f) throw std::runtime_error(landmarks_out + ": cannot write");
  }
  std::cout << "wrote " << args.out << " (" << model.num_vertices() << " vertices, " << model.num_faces()
            << " faces)\n";
  return 0;
}

int Render(const RenderArgs& args) {
  const HeadModel model = LoadHeadModelSpec(args.model);
  const Framing framing = FrameModel(model, args.size);
  const cv::Mat albedo = AlbedoTexture(model);
  const HeadModelParams params = ParamsFromArgs(model, args);
  if (!args.out.empty()) {
    cv::Mat image;
    if (args.view == "front") {
      image = RenderOne(model, params, framing, args.yaw, args.pitch, albedo, args.landmarks);
    } else if (args.view == "side") {
      image = RenderOne(model, params, framing, 90 + args.yaw, args.pitch, albedo, args.landmarks);
    } else if (args.view == "both") {
      cv::hconcat(RenderOne(model, params, framing, args.yaw, args.pitch, albedo, args.landmarks),
                  RenderOne(model, params, framing, 70, args.pitch, albedo, args.landmarks), image);
    } else if (args.view == "grid") {
      // Every expression component at +1 (and the jaw open), 6 per row, for review.
      std::vector<cv::Mat> tiles;
      Framing small = framing;
      small.camera = framing.camera.Resized(256, 256);
      auto tile = [&](const HeadModelParams& p, const std::string& label, double yaw) {
        cv::Mat t = RenderOne(model, p, small, yaw, args.pitch, albedo, args.landmarks);
        Label(&t, label);
        tiles.push_back(t);
      };
      tile(params, "neutral", 0);
      tile(params, "yaw 35", 35);
      tile(params, "yaw -80", -80);
      HeadModelParams jaw = params;
      jaw.pose[3 * kJawJoint] = 0.3;
      tile(jaw, "jaw 0.3 rad", 0);
      tile(jaw, "jaw, yaw 40", 40);
      for (int e = 0; e < model.num_expression(); ++e) {
        HeadModelParams p = params;
        p.expression[e] = 1.0;
        tile(p, model.data().expression_names.empty() ? "expr " + std::to_string(e) : model.data().expression_names[e],
             0);
      }
      for (int s = 0; s < std::min(model.num_shape(), 12); ++s) {
        HeadModelParams p = params;
        p.shape[s] = 2.0;
        tile(p, (model.data().shape_names.empty() ? "shape " + std::to_string(s) : model.data().shape_names[s]) + " +2",
             0);
      }
      const int cols = 6;
      while (tiles.size() % cols) tiles.push_back(cv::Mat(256, 256, CV_8UC3, cv::Scalar(0, 0, 0)));
      std::vector<cv::Mat> rows;
      for (size_t i = 0; i < tiles.size(); i += cols) {
        cv::Mat row;
        cv::hconcat(std::vector<cv::Mat>(tiles.begin() + i, tiles.begin() + i + cols), row);
        rows.push_back(row);
      }
      cv::vconcat(rows, image);
    } else {
      throw std::invalid_argument("--view must be front, side, both or grid");
    }
    WriteImage(args.out, image);
    spdlog::info("wrote {}", args.out);
  }
  if (!args.video.empty()) {
    // A sweep: the head turns, the jaw opens, then each expression in turn.
    VideoWriter writer(args.video, 30);
    const bool all = args.sweep == "all" || args.sweep.empty();
    auto emit = [&](const HeadModelParams& p, double yaw, const std::string& label) {
      cv::Mat f = RenderOne(model, p, framing, yaw, args.pitch, albedo, args.landmarks);
      Label(&f, label);
      writer.Write(f);
    };
    const int steps = 24;
    if (all || args.sweep == "turn")
      for (int i = 0; i < 2 * steps; ++i) emit(params, 45 * std::sin(2 * M_PI * i / (2 * steps)), "head turn");
    if (all || args.sweep == "jaw")
      for (int i = 0; i < steps; ++i) {
        HeadModelParams p = params;
        p.pose[3 * kJawJoint] = 0.35 * std::sin(M_PI * i / steps);
        emit(p, 0, "jaw");
      }
    if (all || args.sweep == "expression")
      for (int e = 0; e < model.num_expression(); ++e)
        for (int i = 0; i < steps; ++i) {
          HeadModelParams p = params;
          p.expression[e] = std::sin(M_PI * i / steps);
          emit(p, 15,
               model.data().expression_names.empty() ? "expression " + std::to_string(e)
                                                     : model.data().expression_names[e]);
        }
    writer.Close();
    spdlog::info("wrote {} ({} frames, 30 fps)", args.video, writer.frames_written());
  }
  return 0;
}

std::string FlameScript(const std::string& given) {
  if (!given.empty()) return given;
  const std::string beside = std::string(HEADCAST_SOURCE_DIR) + "/deploy/tools/flame_to_npz.py";
  return beside;
}

std::string Quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

}  // namespace
}  // namespace headcast

int main(int argc, char** argv) {
  using namespace headcast;
  CLI::App app{"headcast-headmodel: convert, inspect and render head models (FLAME layout)"};
  headcast::AddVersionFlag(app);
  headcast::AddConfigFile(app);
  app.fallthrough();  // global flags (--log, --config) after a subcommand too
  app.require_subcommand(1);
  std::string log_level;
  app.add_option("--log", log_level, "log level: trace, debug, info, warn, error");

  auto* convert = app.add_subcommand("convert", "convert a head-model source into headcast's .npz format");
  convert->require_subcommand(1);
  std::string out;
  // FLAME
  auto* flame = convert->add_subcommand(
      "flame", "official FLAME generic_model.pkl (2020, 2023, 2023 Open) via deploy/tools/flame_to_npz.py");
  std::string flame_pkl, flame_embedding, flame_texture, flame_script;
  int flame_shape = 300, flame_expr = 100;
  flame->add_option("--model", flame_pkl, "generic_model.pkl")->required()->check(CLI::ExistingFile);
  flame->add_option("--embedding", flame_embedding, "landmark_embedding.npy (static + dynamic contour)")
      ->required()
      ->check(CLI::ExistingFile);
  flame->add_option("--texture", flame_texture, "optional FLAME_texture.npz (albedo PCA + UVs)");
  flame->add_option("--shape", flame_shape, "shape components to keep")->capture_default_str();
  flame->add_option("--expression", flame_expr, "expression components to keep")->capture_default_str();
  flame->add_option("--script", flame_script, "path of flame_to_npz.py (default: the source tree's)");
  flame->add_option("--out", out, "output .npz")->required();
  // ICT
  auto* ict = convert->add_subcommand("ict", "ICT-FaceKit upstream folder (FaceXModel)");
  IctConvertOptions ict_options;
  std::string ict_parts;
  ict->add_option("--folder", ict_options.folder, "ICT-FaceKit folder (contains FaceXModel/)")->required();
  ict->add_option("--identity", ict_options.max_identity, "identity components to read")->capture_default_str();
  ict->add_option(
      "--parts", ict_parts,
      "comma-separated parts to keep: face,head,mouth,eyes,gums_tongue,teeth,eyeballs,eye_accessories, or all "
      "(default: all but eye_accessories, which would cover the eyeballs)");
  ict->add_flag("--paint-parts,!--no-paint-parts", ict_options.paint_parts,
                "paint an albedo (upstream has none): each part a plain colour, the eyeballs a sclera, iris and pupil "
                "(off: every part rendered skin-coloured)")
      ->capture_default_str();
  ict->add_option("--out", out, "output .npz")->required();
  HeadModelSaveOptions save;
  const char* step_help =
      "store the bases as int16 steps of this many metres (compact, e.g. 5e-6: what models/ ships; 0: float32)";
  ict->add_option("--basis-step", save.basis_step, step_help)->check(CLI::Range(0.0, 1e-3))->capture_default_str();
  // Built-in
  auto* builtin = convert->add_subcommand("builtin", "write the built-in procedural head as .npz");
  builtin->add_option("--out", out, "output .npz")->required();
  builtin->add_option("--basis-step", save.basis_step, step_help)->check(CLI::Range(0.0, 1e-3))->capture_default_str();

  auto* summary = app.add_subcommand("summary", "print a model's sizes, joints, landmarks and component names");
  std::string summary_model;
  summary->add_option("model", summary_model, "builtin or a model .npz")->required();

  auto* render = app.add_subcommand("render", "render a model to PNG (views, grid) and/or an MP4 sweep");
  RenderArgs r;
  render->add_option("model", r.model, "builtin or a model .npz")->required();
  render->add_option("--out", r.out, "PNG to write");
  render->add_option("--video", r.video, "MP4 sweep to write");
  render->add_option("--sweep", r.sweep, "what the video sweeps: all, turn, jaw, expression")
      ->check(CLI::IsMember({"all", "turn", "jaw", "expression"}));
  render->add_option("--view", r.view, "front, side, both, grid")
      ->check(CLI::IsMember({"front", "side", "both", "grid"}));
  render->add_option("--size", r.size, "image size, pixels")->check(CLI::Range(64, 4096));
  render->add_option("--yaw", r.yaw, "head yaw, degrees");
  render->add_option("--pitch", r.pitch, "head pitch, degrees");
  render->add_option("--jaw", r.jaw_deg, "jaw opening, degrees");
  render->add_option("--expression", r.expressions, "name=value, repeatable");
  render->add_flag("--landmarks", r.landmarks, "draw the 68 landmarks");

  RenderArgs x;
  std::string landmarks_out;
  auto* export_mesh = app.add_subcommand("export", "write a posed model mesh (.obj/.ply) and its landmarks");
  export_mesh->add_option("model", x.model, "builtin or a model .npz")->required();
  export_mesh->add_option("--out", x.out, ".obj or .ply to write")->required();
  export_mesh->add_option("--jaw", x.jaw_deg, "jaw opening, degrees");
  export_mesh->add_option("--expression", x.expressions, "name=value, repeatable");
  export_mesh->add_option("--shape", x.shapes, "index=value, repeatable");
  export_mesh->add_option("--landmarks-out", landmarks_out, "also write the 68 landmarks (JSON)");

  RenderArgs g;
  RgbdRenderOptions rgbd;
  auto* render_rgbd = app.add_subcommand(
      "render-rgbd", "a synthetic RGB-D sequence of the talking head (colour, mm depth, associations.txt, truth.json)");
  render_rgbd->add_option("model", g.model, "builtin or a model .npz")->required();
  render_rgbd->add_option("--out", g.out, "folder to write")->required();
  render_rgbd->add_option("--frames", rgbd.frames, "frames")->check(CLI::Range(1, 100000));
  render_rgbd->add_option("--size", rgbd.width, "image width (height = 3/4 of it)")->check(CLI::Range(64, 4096));
  render_rgbd->add_option("--fov", rgbd.fov_deg, "vertical field of view, degrees")->capture_default_str();
  render_rgbd->add_option("--depth-noise", rgbd.noise_mm, "Gaussian depth noise, mm")->capture_default_str();
  render_rgbd
      ->add_option("--stereo-baseline", rgbd.stereo_baseline_m,
                   "metres: also side-by-side stereo frames (side_by_side/) and their calibration (stereo.yml), "
                   "for zed:OUT/side_by_side --stereo-calibration OUT/stereo.yml")
      ->check(CLI::Range(0.0, 1.0));
  render_rgbd->add_option("--shape", g.shapes, "index=value, repeatable (the subject's identity)");
  render_rgbd
      ->add_option("--first-frame", rgbd.first_frame,
                   "start this many frames into the synthetic motion (files and times still count from 0)")
      ->check(CLI::Range(0, 1000000));

  CLI11_PARSE(app, argc, argv);
  try {
    InitLogging(log_level);
    if (flame->parsed()) {
      const std::string python = std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
      std::string cmd = python + " " + Quote(FlameScript(flame_script)) + " --model " + Quote(flame_pkl) +
                        " --embedding " + Quote(flame_embedding) + " --shape " + std::to_string(flame_shape) +
                        " --expression " + std::to_string(flame_expr) + " --out " + Quote(out);
      if (!flame_texture.empty()) cmd += " --texture " + Quote(flame_texture);
      spdlog::info("running {}", cmd);
      if (std::system(cmd.c_str()) != 0) {
        spdlog::error("FLAME conversion failed (see the script's message above)");
        return 1;
      }
      std::cout << LoadHeadModel(out).Summary();
    } else if (ict->parsed()) {
      if (!ict_parts.empty()) {  // else IctDefaultParts(); "all" leaves the list empty: every part
        ict_options.parts.clear();
        std::stringstream ss(ict_parts == "all" ? "" : ict_parts);
        for (std::string part; std::getline(ss, part, ',');)
          if (!part.empty()) ict_options.parts.push_back(part);
      }
      const HeadModel model = ConvertIctFaceKit(ict_options);
      SaveHeadModel(model, out, save);
      std::cout << LoadHeadModel(out).Summary() << "wrote " << out << "\n";  // as read back
    } else if (builtin->parsed()) {
      const HeadModel model = MakeBuiltinHead();
      SaveHeadModel(model, out, save);
      std::cout << LoadHeadModel(out).Summary() << "wrote " << out << "\n";  // as read back
    } else if (summary->parsed()) {
      std::cout << LoadHeadModelSpec(summary_model).Summary();
    } else if (render->parsed()) {
      if (r.out.empty() && r.video.empty()) throw std::invalid_argument("render: give --out PNG and/or --video MP4");
      return Render(r);
    } else if (export_mesh->parsed()) {
      return Export(x, landmarks_out);
    } else if (render_rgbd->parsed()) {
      return RenderRgbd(g, rgbd);
    }
  } catch (const std::exception& e) {
    spdlog::error("{}", headcast::InFlagNames(app, e.what()));
    return 1;
  }
  return 0;
}
