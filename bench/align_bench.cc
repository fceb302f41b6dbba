// Registration speed: scaled point-to-plane ICP of a noisy, similarity-moved copy of a sampled building
// (N source points against the same number of target points, start 2° / 2% off), kd-tree build + queries,
// and the CAD comparison's distance pass. Run: build/bench/align_bench --benchmark_min_time=1
//
// BM_TwoFlightsDifferentSides (issue 7, "the merged model's completeness ≥ the better single track's + 5
// points when the flights see different sides; accuracy no worse"): two synthetic orbits of the building —
// other camera, size, distortion, altitude, radius, sun, exposure, seed — each cut to a 200° arc on opposite
// sides (A from the south over the east to the north, B from the north over the west to the south; they share
// ~20° at each end), each reconstructed (frames, features, match, sparse, dense at 480 px), then
// `fmv3d align --union A B -o AB` (the union of the two clouds) and `fmv3d align A B -o ABr` (the default:
// dense recomputed over the merged model). The merged clouds and each track's part of the union are evaluated with
// mvs::EvaluateDense against the reference track's truth (its full 36-frame orbit decides which surface is "seen"), so
// all three figures share one alignment and one visible surface. Opt-in (tens of CPU-minutes):
//   FMV3D_ALIGN_BENCH_DIR=<scratch folder> build/bench/align_bench --benchmark_filter=TwoFlights
// The flights are kept in that folder and reused on the next run (delete it to rebuild them).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "fmv3d/align/icp.h"
#include "fmv3d/align/merge.h"
#include "fmv3d/align/point_index.h"
#include "fmv3d/align/sim3_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/mvs/evaluation.h"
#include "fmv3d/sfm/evaluation.h"
#include "fmv3d/synth/scene.h"

namespace {

using namespace fmv3d;

io::OrientedPointCloud Building(size_t target_points) {
  const io::TexturedMesh mesh = synth::MakeBuilding(synth::BuildingSpec{}, 0);
  const geometry::MeshDistance md(mesh);
  const double spacing = std::sqrt(mesh.SurfaceArea() / target_points);
  std::vector<int> faces;
  io::OrientedPointCloud c;
  c.positions = md.SampleSurface(spacing, &faces, 1);
  for (int f : faces) c.normals.push_back(md.Normal(f).cast<float>());
  return c;
}

void BM_ScaledIcp(benchmark::State& state) {
  const io::OrientedPointCloud a = Building(state.range(0));
  core::Sim3 truth;
  truth.s = 1.7;
  truth.q = Eigen::AngleAxisd(1.0, Eigen::Vector3d(1, 2, 3).normalized());
  truth.t = Eigen::Vector3d(5, -3, 2);
  std::mt19937_64 rng(1);
  std::normal_distribution<double> g(0, 0.005);
  io::OrientedPointCloud b;
  for (const auto& p : a.positions) b.positions.push_back(truth.Apply(p) + Eigen::Vector3d{g(rng), g(rng), g(rng)});
  core::Sim3 off;
  off.s = 1.02;
  off.q = Eigen::AngleAxisd(2 * M_PI / 180, Eigen::Vector3d::UnitZ());
  const core::Sim3 start = align::ComposeSim3(off, truth.Inverse());
  const align::IcpTarget target(a);
  align::IcpOptions o;
  o.max_source_points = 0;
  int iterations = 0;
  for (auto _ : state) {
    const auto r = align::ScaledIcp(b, target, start, o);
    iterations = r.iterations;
    benchmark::DoNotOptimize(r.transform.s);
  }
  state.counters["points"] = static_cast<double>(a.size());
  state.counters["iterations"] = iterations;
}
BENCHMARK(BM_ScaledIcp)->Arg(20000)->Arg(100000)->Unit(benchmark::kMillisecond);

void BM_PointIndexBuildAndQuery(benchmark::State& state) {
  const io::OrientedPointCloud a = Building(state.range(0));
  for (auto _ : state) {
    const align::PointIndex index(a.positions);
    double sum = 0;
    for (const auto& p : a.positions) {
      double d2 = 0;
      index.Nearest(p + Eigen::Vector3d(0.01, 0.02, 0.03), &d2);
      sum += d2;
    }
    benchmark::DoNotOptimize(sum);
  }
  state.counters["points"] = static_cast<double>(a.size());
}
BENCHMARK(BM_PointIndexBuildAndQuery)->Arg(100000)->Arg(1000000)->Unit(benchmark::kMillisecond);

namespace fs = std::filesystem;

void Run(const fs::path& fmv3d, const std::string& args) {
  const std::string cmd = "'" + fmv3d.string() + "' -q " + args;
  std::printf("$ fmv3d -q %s\n", args.c_str());
  std::fflush(stdout);
  if (std::system(cmd.c_str()) != 0) throw Error("failed: " + cmd);
}

// synth a full orbit, keep the arc [first, first + count) (mod frames) as the track's video, reconstruct it.
void ArcFlight(const fs::path& fmv3d, const fs::path& root, const std::string& name, const std::string& synth_args,
               int frames, int first, int count) {
  const fs::path ws = root / name, synth = root / ("synth_" + name), src = root / ("arc_" + name);
  if (fs::exists(ws / "dense" / "fused.ply")) return;
  if (!fs::exists(synth / "truth.json"))
    Run(fmv3d, "synth --scene building --path orbit --frames " + std::to_string(frames) + " " + synth_args + " -o " +
                   synth.string());
  fs::remove_all(src);
  fs::create_directories(src);
  for (int k = 0; k < count; ++k) {
    char file[64];
    std::snprintf(file, sizeof file, "flight-%06d.png", (first + k) % frames);
    fs::copy_file(synth / "frames" / file, src / file);
  }
  fs::remove_all(ws);
  Run(fmv3d, "frames " + src.string() + " -o " + ws.string());
  Run(fmv3d, "features " + ws.string());
  Run(fmv3d, "match " + ws.string());
  Run(fmv3d, "sparse " + ws.string());
  Run(fmv3d, "dense --max-size 480 --no-previews " + ws.string());
}

struct Truth {
  core::Reconstruction cameras;
  io::TexturedMesh scene;
  double length = 0;
  mvs::DenseEvaluationOptions options;
};

Truth LoadSynthTruth(const fs::path& synth) {
  Truth t;
  t.cameras = io::ReadColmapText(synth / "truth");
  t.scene = io::ReadObj(synth / "scene.obj", false);
  const auto j = core::ReadJson(synth / "truth.json");
  t.length = j.at("characteristic_length").get<double>();
  const auto& b = j.at("bounds");
  t.options.region = Eigen::AlignedBox3d(
      Eigen::Vector3d(b.at("min")[0].get<double>(), b.at("min")[1].get<double>(), b.at("min")[2].get<double>()),
      Eigen::Vector3d(b.at("max")[0].get<double>(), b.at("max")[1].get<double>(), b.at("max")[2].get<double>()));
  return t;
}

io::OrientedPointCloud Slice(const io::OrientedPointCloud& c, size_t begin, size_t end) {
  io::OrientedPointCloud out;
  out.positions.assign(c.positions.begin() + begin, c.positions.begin() + end);
  if (c.has_normals()) out.normals.assign(c.normals.begin() + begin, c.normals.begin() + end);
  return out;
}

void BM_TwoFlightsDifferentSides(benchmark::State& state) {
  const char* dir = std::getenv("FMV3D_ALIGN_BENCH_DIR");
  if (!dir) {
    state.SkipWithError("set FMV3D_ALIGN_BENCH_DIR=<scratch folder> to run the two-flight measurement");
    return;
  }
  const fs::path root = dir, fmv3d = fs::read_symlink("/proc/self/exe").parent_path().parent_path() / "fmv3d";
  fs::create_directories(root);
  ArcFlight(fmv3d, root, "A", "--size 640x360 --seed 1", 36, 0, 20);
  ArcFlight(fmv3d, root, "B",
            "--size 704x396 --focal 520 --distortion -0.05,0.01,0,0 --altitude 40 --radius 65 --sun-azimuth 250 "
            "--exposure 0.85 --seed 2",
            36, 17, 20);
  for (auto _ : state) {
    if (std::getenv("FMV3D_ALIGN_BENCH_REUSE_MERGED") && fs::exists(root / "AB" / "report" / "align.json") &&
        fs::exists(root / "ABr" / "report" / "align.json"))
      continue;
    // AB: the union of the two clouds (each track's part stays separable); ABr: the default, dense recomputed
    // over the merged model.
    fs::remove_all(root / "AB");
    Run(fmv3d,
        "align --union " + (root / "A").string() + " " + (root / "B").string() + " -o " + (root / "AB").string());
    fs::remove_all(root / "ABr");
    Run(fmv3d, "align " + (root / "A").string() + " " + (root / "B").string() + " -o " + (root / "ABr").string());
  }
  const auto report = core::ReadJson(root / "AB" / "report" / "align.json");
  const std::string ref = report.at("reference").get<std::string>();
  const size_t ref_index = report.at("tracks")[0].at("name") == ref ? 0 : 1;
  const size_t ref_points = report.at("tracks")[ref_index].at("dense_points").get<size_t>();
  const Truth truth = LoadSynthTruth(root / ("synth_" + ref));
  const core::Reconstruction merged_sparse = io::ReadColmapText(root / "AB" / "sparse");
  const io::OrientedPointCloud merged = io::ReadPointCloudPly(root / "AB" / "dense" / "fused.ply");
  const std::string mov = ref == "A" ? "B" : "A";
  struct Row {
    std::string what;
    mvs::DenseEvaluation ev;
  };
  std::vector<Row> rows;
  auto eval = [&](const std::string& what, const io::OrientedPointCloud& cloud) {
    rows.push_back(
        {what, mvs::EvaluateDense(cloud, merged_sparse, truth.cameras, truth.scene, truth.length, truth.options)});
  };
  eval(ref + " (reference)", Slice(merged, 0, ref_points));
  eval(mov + " (aligned)", Slice(merged, ref_points, merged.size()));
  eval("merged", merged);
  // The same union with only the finer track's points where both cover the surface (align --keep-finer).
  align::MergedModel finer;
  finer.sparse = merged_sparse;
  finer.dense = merged;
  finer.dense_ranges = {{0, ref_points}, {ref_points, merged.size()}};
  align::KeepFinerInOverlap(&finer);
  eval("merged, finer", finer.dense);
  // The surface both tracks cover: points with a point of the other track within 2 median spacings (of the
  // other track). There the union is compared with each track on the same surface.
  auto in_overlap = [&](size_t begin, size_t end, size_t obegin, size_t oend) {
    std::vector<Eigen::Vector3d> other(merged.positions.begin() + obegin, merged.positions.begin() + oend);
    const align::PointIndex index(other);
    const double r = 2 * align::MedianSpacing(other, index);
    io::OrientedPointCloud out;
    for (size_t i = begin; i < end; ++i) {
      double d2 = 0;
      if (index.Nearest(merged.positions[i], &d2) >= 0 && d2 <= r * r) {
        out.positions.push_back(merged.positions[i]);
        if (merged.has_normals()) out.normals.push_back(merged.normals[i]);
      }
    }
    return out;
  };
  const io::OrientedPointCloud ref_common = in_overlap(0, ref_points, ref_points, merged.size());
  const io::OrientedPointCloud mov_common = in_overlap(ref_points, merged.size(), 0, ref_points);
  io::OrientedPointCloud union_common = ref_common;
  union_common.Append(mov_common);
  eval(ref + " where both", ref_common);
  eval(mov + " where both", mov_common);
  eval("merged where both", union_common);
  // The dense stage run again over the merged model (the default), on its own and where both tracks' clouds
  // have a point within 2 spacings.
  const io::OrientedPointCloud recomputed = io::ReadPointCloudPly(root / "ABr" / "dense" / "fused.ply");
  rows.push_back({"recomputed", mvs::EvaluateDense(recomputed, io::ReadColmapText(root / "ABr" / "sparse"),
                                                   truth.cameras, truth.scene, truth.length, truth.options)});
  {
    std::vector<Eigen::Vector3d> pa(merged.positions.begin(), merged.positions.begin() + ref_points),
        pb(merged.positions.begin() + ref_points, merged.positions.end());
    const align::PointIndex ia(pa), ib(pb);
    const double ra = 2 * align::MedianSpacing(pa, ia), rb = 2 * align::MedianSpacing(pb, ib);
    io::OrientedPointCloud both;
    for (size_t i = 0; i < recomputed.size(); ++i) {
      double da = 0, db = 0;
      if (ia.Nearest(recomputed.positions[i], &da) >= 0 && da <= ra * ra &&
          ib.Nearest(recomputed.positions[i], &db) >= 0 && db <= rb * rb)
        both.positions.push_back(recomputed.positions[i]);
    }
    rows.push_back(
        {"recomputed where both", mvs::EvaluateDense(both, io::ReadColmapText(root / "ABr" / "sparse"), truth.cameras,
                                                     truth.scene, truth.length, truth.options)});
  }
  // What no selection between the two clouds can beat: the better track's points wherever both see the surface
  // (chosen with the truth), the other track's elsewhere. Its median is worse than the union's: the surface only
  // the worse track sees weighs more.
  {
    const bool mov_better = rows[1].ev.median_error < rows[0].ev.median_error;
    const size_t keep_begin = mov_better ? ref_points : 0, keep_end = mov_better ? merged.size() : ref_points;
    const size_t cut_begin = mov_better ? 0 : ref_points, cut_end = mov_better ? ref_points : merged.size();
    std::vector<Eigen::Vector3d> keep(merged.positions.begin() + keep_begin, merged.positions.begin() + keep_end);
    const align::PointIndex index(keep);
    const double r = 2 * align::MedianSpacing(keep, index);
    io::OrientedPointCloud out = Slice(merged, keep_begin, keep_end);
    for (size_t i = cut_begin; i < cut_end; ++i) {
      double d2 = 0;
      if (index.Nearest(merged.positions[i], &d2) >= 0 && d2 <= r * r) continue;
      out.positions.push_back(merged.positions[i]);
      if (merged.has_normals()) out.normals.push_back(merged.normals[i]);
    }
    eval("oracle selection", out);
  }
  std::printf("\n%-16s %9s %14s %12s %14s\n", "cloud", "points", "median err %L", "p90 err %L", "completeness");
  for (const auto& r : rows)
    std::printf("%-18s %9zu %14.3f %12.3f %13.2f%%\n", r.what.c_str(), r.ev.points, 100 * r.ev.median_fraction(),
                100 * r.ev.p90_fraction(), 100 * r.ev.completeness);
  const double better = std::max(rows[0].ev.completeness, rows[1].ev.completeness);
  std::printf(
      "completeness gain over the better single track: %+.2f points union, %+.2f finer kept, %+.2f "
      "recomputed (target >= +5)\n",
      100 * (rows[2].ev.completeness - better), 100 * (rows[3].ev.completeness - better),
      100 * (rows[7].ev.completeness - better));
  if (report.contains("joint_bundle_adjustment"))
    std::printf("joint BA: %s\n", report.at("joint_bundle_adjustment").dump().c_str());
  std::printf("alignment: %s\n", report.at("tree")[0].dump().c_str());
  // The similarity B → A against the truth (each track's own cameras aligned to its flight's truth).
  const core::Reconstruction rec_ref = io::ReadColmapText(root / ref / "sparse");
  const core::Reconstruction rec_mov = io::ReadColmapText(root / mov / "sparse");
  const auto eval_ref = sfm::EvaluateSparse(rec_ref, sfm::LoadTruth((root / ("synth_" + ref) / "truth").string()));
  const auto eval_mov = sfm::EvaluateSparse(rec_mov, sfm::LoadTruth((root / ("synth_" + mov) / "truth").string()));
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& [id, p] : rec_mov.points) centroid += eval_mov.alignment.Apply(p.xyz);
  centroid /= static_cast<double>(std::max<size_t>(1, rec_mov.points.size()));
  const auto& moving_track = report.at("tracks")[1 - ref_index];
  std::printf("track centre RMSE vs truth: %s %.4f%%, %s %.4f%%\n", ref.c_str(), 100 * eval_ref.centre_rmse_fraction,
              mov.c_str(), 100 * eval_mov.centre_rmse_fraction);
  for (const char* key : {"to_reference", "to_reference_after_joint_ba"}) {
    if (!moving_track.contains(key)) continue;
    const auto e =
        sfm::CompareSimilarityToTruth(align::Sim3FromJson(moving_track.at(key)), eval_ref, eval_mov, centroid);
    std::printf(
        "similarity %s vs truth: rotation %.4f deg, scale %.4f%%, translation %.4f%% of the scene "
        "(bounds 0.05 deg, 0.1%%, 0.1%%)\n",
        key, e.rotation_deg, 100 * e.scale, 100 * e.translation_fraction);
    state.counters[std::string(key) + "_rotation_deg"] = e.rotation_deg;
    state.counters[std::string(key) + "_scale_pct"] = 100 * e.scale;
  }
  // B's registration onto A inside the merged model: each part aligned to its own truth (one world); the joint
  // BA moves the reference's cameras too, which the composed similarity above counts as error.
  const auto [merged_ref_part, merged_mov_part] = align::SplitByNamePrefix(merged_sparse, mov + "-");
  const auto in_ref =
      sfm::EvaluateSparse(merged_ref_part, sfm::LoadTruth((root / ("synth_" + ref) / "truth").string()));
  const auto in_mov =
      sfm::EvaluateSparse(merged_mov_part, sfm::LoadTruth((root / ("synth_" + mov) / "truth").string()));
  const auto m = sfm::CompareSimilarityToTruth(core::Sim3{}, in_ref, in_mov, centroid);
  std::printf(
      "in the merged model, %s registered onto %s vs truth: rotation %.4f deg, scale %.4f%%, translation "
      "%.4f%% of the scene\n",
      mov.c_str(), ref.c_str(), m.rotation_deg, 100 * m.scale, 100 * m.translation_fraction);
  state.counters["merged_rotation_deg"] = m.rotation_deg;
  state.counters["merged_scale_pct"] = 100 * m.scale;
  state.counters["completeness_ref"] = rows[0].ev.completeness;
  state.counters["completeness_mov"] = rows[1].ev.completeness;
  state.counters["completeness_merged"] = rows[2].ev.completeness;
  state.counters["median_ref_pct"] = 100 * rows[0].ev.median_fraction();
  state.counters["median_mov_pct"] = 100 * rows[1].ev.median_fraction();
  state.counters["median_merged_pct"] = 100 * rows[2].ev.median_fraction();
  state.counters["completeness_finer"] = rows[3].ev.completeness;
  state.counters["median_finer_pct"] = 100 * rows[3].ev.median_fraction();
  state.counters["completeness_recomputed"] = rows[7].ev.completeness;
  state.counters["median_recomputed_pct"] = 100 * rows[7].ev.median_fraction();
  state.counters["p90_recomputed_pct"] = 100 * rows[7].ev.p90_fraction();
}
BENCHMARK(BM_TwoFlightsDifferentSides)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
