// Benchmark suite "meshfit": fitting the head model to synthetic scans with
// known parameters (METHOD §8) — face accuracy with the importance weights
// against uniform weights, with hair the model cannot produce, for both
// losses; the other-topology case; time per fit.
#include "bench/bench.h"
#include "common/headmodel/head_model_io.h"
#include "common/tracking/synthetic_scan.h"

namespace headcast::bench {

nlohmann::json RunMeshFitSuite(const BenchOptions& options) {
  const HeadModel model = LoadHeadModelSpec(options.head_model);
  const int trials = std::max(1, options.repeats);
  const struct {
    const char* name;
    MeshWeighting weighting;
  } weightings[] = {{"uniform", MeshWeighting::kUniform},
                    {"importance", MeshWeighting::kImportance},
                    {"importance_count", MeshWeighting::kImportanceAndCount}};
  const struct {
    const char* name;
    MeshLoss loss;
  } losses[] = {{"squared", MeshLoss::kSquared}, {"norm", MeshLoss::kNorm}};
  nlohmann::json out;
  out["suite"] = "meshfit";
  out["head_model"] = model.data().name;
  out["vertices"] = model.num_vertices();
  out["trials"] = trials;
  out["what"] =
      "face RMS distance (importance >= 1) between the fitted model and the true scan, mm, mean over trials; scans: "
      "random shape/expression/jaw and rigid pose, 0.3 mm vertex noise, with and without 12 mm of hair";
  for (double hair : {0.0, 0.012}) {
    const std::string scenario = hair > 0 ? "hair_12mm" : "clean";
    for (const auto& l : losses)
      for (const auto& w : weightings) {
        SampleStats face_mm, ms;
        for (int t = 0; t < trials; ++t) {
          SyntheticScanOptions so;
          so.seed = 100 + t;
          so.noise_m = 0.3e-3;
          so.hair_m = hair;
          const SyntheticScan scan = MakeSyntheticScan(model, so);
          MeshFitOptions o;
          o.weighting = w.weighting;
          o.loss = l.loss;
          Stopwatch watch;
          const MeshFitResult fit = FitHeadModelToMesh(model, TriangleMesh{scan.noisy, model.data().faces}, o);
          ms.Add(watch.ElapsedMs());
          face_mm.Add(FaceRmsAgainstTruthMm(model, fit, scan.clean));
        }
        out[scenario][l.name][w.name] = {{"face_rms_mm", face_mm.Mean()}, {"ms_per_fit_median", ms.Median()}};
      }
  }
  // Another topology: the clean scan decimated (vertex clustering, 6 mm cells), nine noisy landmarks.
  {
    SampleStats face_mm, ms;
    for (int t = 0; t < trials; ++t) {
      SyntheticScanOptions so;
      so.seed = 200 + t;
      so.noise_m = 0;
      const SyntheticScan scan = MakeSyntheticScan(model, so);
      const TriangleMesh coarse = ClusterDecimate(TriangleMesh{scan.clean, model.data().faces}, 0.006);
      MeshFitOptions o;
      const HeadModelOutput posed = model.Forward(scan.params);
      for (int i : {36, 39, 42, 45, 30, 33, 48, 54, 8})
        o.target_landmarks.emplace_back(
            i, scan.rotation * posed.landmarks.row(i).cast<double>().transpose() + scan.translation);
      Stopwatch watch;
      const MeshFitResult fit = FitHeadModelToMesh(model, coarse, o);
      ms.Add(watch.ElapsedMs());
      face_mm.Add(FaceRmsAgainstTruthMm(model, fit, scan.clean));
      out["other_topology"]["target_vertices"] = coarse.vertices.rows();
    }
    out["other_topology"]["face_rms_mm"] = face_mm.Mean();
    out["other_topology"]["ms_per_fit_median"] = ms.Median();
    out["other_topology"]["what"] = "decimated copy (6 mm vertex clustering) of a clean scan; closest points";
  }
  return out;
}

}  // namespace headcast::bench
