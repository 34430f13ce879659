// Benchmark suite "raster": rasterising (and shading) the built-in head.
#include "bench/bench.h"
#include "common/headmodel/builtin_head.h"
#include "common/headmodel/head_render.h"

namespace headcast::bench {

nlohmann::json RunRasterSuite(const BenchOptions& options) {
  nlohmann::json out;
  out["suite"] = "raster";
  out["what"] =
      "CPU rasteriser on the built-in head (z-buffer, face ids, perspective-correct barycentrics), milliseconds";
  const HeadModel model = MakeBuiltinHead();
  out["vertices"] = model.num_vertices();
  out["faces"] = model.num_faces();
  const HeadModelOutput posed = model.Forward(HeadModelParams{});
  const RigidTransform cam_from_head = FrontalCamFromHead(0.75, 20, 5);
  const cv::Mat albedo = AlbedoTexture(model);
  for (int size : {128, 256, 512}) {
    const PinholeCamera camera = PinholeCamera::FromFovY(size, size, 24);
    RasterVertices v_cam;
    TransformToCamera(posed.vertices, cam_from_head, &v_cam);
    RasterBuffers buffers;
    RasterOptions raster_options;
    const SampleStats raster =
        TimeUs(options, [&] { Rasterize(v_cam, model.data().faces, camera, raster_options, &buffers); });
    const std::string s = std::to_string(size);
    out["raster_ms_median_" + s] = raster.Median() / 1e3;
    out["raster_ms_p95_" + s] = raster.Percentile(95) / 1e3;
    out["covered_pixels_" + s] = buffers.CoveredPixels();
    BenchOptions fewer = options;
    fewer.repeats = std::max(1, options.repeats / 4);
    const SampleStats shaded =
        TimeUs(fewer, [&] { (void)RenderHead(model, posed.vertices, cam_from_head, camera, albedo, {}, &buffers); });
    out["render_shaded_ms_median_" + s] = shaded.Median() / 1e3;
  }
  return out;
}

}  // namespace headcast::bench
