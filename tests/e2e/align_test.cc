// Track alignment end to end: two synthetic flights of one scene — different path, focal length, image size, lens
// distortion, sun direction, exposure and seed — reconstructed separately (frames → features → match →
// sparse), then `fmv3d align`. The recovered similarity B → A is checked against the truth composed from each
// model's own alignment to the ground truth (sfm::EvaluateSparse, camera centres, Umeyama):
//   truth(B → A) = S_A⁻¹ ∘ S_B.
// Errors are measured in the ground-truth frame: E = S_A ∘ found ∘ S_B⁻¹ should be the identity; rotation
// angle of E, |scale − 1|, and the displacement E moves the centroid of B's points by, as a fraction of the
// scene size (the largest distance between two true camera centres of A, the extent the sparse figures use).
// Note the yardstick: S_A and S_B carry each model's own error (centre RMSE of a few 0.01% of the extent).
// CI cost: 30 frames of 800x450 and 864x486, 3000 features per image, sequential matching (each frame with
// the next 5, 2^k and loop-closure pairs) instead of 36 frames of ~1000x560, 8000 features, exhaustive
// pairs (469 s). The two flights run concurrently (their sparse stages are largely serial).
// The merged model then gets the joint bundle adjustment; its reprojection RMS is checked too. Then both
// tracks get a small dense cloud (240 px) and are merged again, by default (dense recomputed over the merged
// model) and with --union: the recomputed cloud must be no less accurate than the union (median) and as
// complete as the better track (both flights are full orbits here, so the completeness gain is small; the +5 points of
// different sides and the comparison with each track are measured in bench/align_bench).
// Measured (heavily shared 2 cores): coarse similarity 0.044°, 0.116%, 0.046%; after the joint BA (4369 of
// 5386 cross-track links fused, 0.46 → 0.42 px) 0.046°, 0.043%, 0.018% of the scene size; the models' centre
// RMSE 0.019% and 0.043%. The cheaper flights' B model is the yardstick's weak side (scale alone fails 0.1%).
//
// Set FMV3D_E2E_ALIGN_DIR to keep the flights and reuse them on the next run (development only).
#include <gtest/gtest.h>

#include <thread>

#include "fmv3d/align/merge.h"
#include "fmv3d/align/sim3_json.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/sfm/evaluation.h"
#include "test_util.h"

namespace fmv3d::test {
namespace {

void Cli(const std::string& args) {
  const auto r = RunCli(args);
  ASSERT_EQ(r.exit_code, 0) << "fmv3d " << args << "\n" << r.err;
}

// Runs one flight through synth → sparse; returns "" or the failing command and its error (callable from a
// thread, unlike gtest assertions).
std::string Flight(const fs::path& root, const std::string& name, const std::string& synth_args) {
  const std::string synth = (root / ("synth_" + name)).string(), ws = (root / name).string();
  if (fs::exists(root / name / "sparse" / "images.txt")) return "";
  std::string synth_command = "-q synth --scene building ", frames_command = "-q frames ";
  synth_command.append(synth_args).append(" -o ").append(synth);
  frames_command.append(synth).append("/frames -o ").append(ws);
  for (const std::string& args : {synth_command, frames_command, "-q features --max-features 3000 " + ws,
                                  "-q match --pairs sequential --overlap 5 " + ws, "-q sparse " + ws}) {
    const auto r = RunCli(args);
    if (r.exit_code != 0) return "fmv3d " + args + "\n" + r.err;
  }
  return "";
}

TEST(E2eAlign, TwoSyntheticFlightsOfOneScene) {
  std::unique_ptr<TempDir> tmp;
  fs::path root;
  if (const char* keep = std::getenv("FMV3D_E2E_ALIGN_DIR")) {
    root = keep;
    fs::create_directories(root);
  } else {
    tmp = std::make_unique<TempDir>("fmv3d-e2e-align");
    root = tmp->path();
  }
  // With 24 frames at 640x360 the models themselves are only good to ~0.08% (centre RMSE), and the
  // yardstick then fails the bounds (measured 0.087°, 0.16%, 0.057%): 30 frames of ~800x450.
  std::string error_a, error_b;
  std::thread a([&] { error_a = Flight(root, "A", "--path orbit --frames 30 --size 800x450 --seed 1"); });
  error_b = Flight(root, "B",
                   "--path orbit --frames 30 --size 864x486 --focal 750 --distortion -0.06,0.01,0,0 "
                   "--altitude 45 --radius 70 --sun-azimuth 250 --exposure 0.8 --seed 2");
  a.join();
  ASSERT_EQ(error_a, "");
  ASSERT_EQ(error_b, "");
  fs::remove_all(root / "AB");
  Cli("-q align " + (root / "A").string() + " " + (root / "B").string() + " -o " + (root / "AB").string());

  const auto report = core::ReadJson(root / "AB/report/align.json");
  const bool a_is_ref = report.at("reference").get<std::string>() == "A";
  const auto& moving_track = report.at("tracks")[a_is_ref ? 1 : 0];
  const core::Sim3 found = align::Sim3FromJson(moving_track.at("to_reference"));
  const core::Sim3 after_ba = align::Sim3FromJson(moving_track.at("to_reference_after_joint_ba"));
  const fs::path ref = a_is_ref ? "A" : "B", mov = a_is_ref ? "B" : "A";
  const core::Reconstruction rec_ref = io::ReadColmapText(root / ref / "sparse");
  const core::Reconstruction rec_mov = io::ReadColmapText(root / mov / "sparse");
  const auto eval_ref =
      sfm::EvaluateSparse(rec_ref, sfm::LoadTruth((root / ("synth_" + ref.string()) / "truth").string()));
  const auto eval_mov =
      sfm::EvaluateSparse(rec_mov, sfm::LoadTruth((root / ("synth_" + mov.string()) / "truth").string()));

  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& [id, p] : rec_mov.points) centroid += eval_mov.alignment.Apply(p.xyz);
  centroid /= rec_mov.points.size();
  struct Errors {
    double rotation_deg, scale_err, translation_frac;
  };
  auto errors = [&](const core::Sim3& sim) {
    const sfm::SimilarityError e = sfm::CompareSimilarityToTruth(sim, eval_ref, eval_mov, centroid);
    return Errors{e.rotation_deg, e.scale, e.translation_fraction};
  };
  const auto [rotation_deg, scale_err, translation_frac] = errors(found);
  const Errors ba = errors(after_ba);
  std::cout << "align B → A vs truth: rotation " << rotation_deg << " deg, scale " << 100 * scale_err
            << " %, translation " << 100 * translation_frac << " % of the scene size (" << eval_ref.extent
            << " m); after the joint BA: " << ba.rotation_deg << " deg, " << 100 * ba.scale_err << " %, "
            << 100 * ba.translation_frac << " %; yardstick: centre RMSE of the models "
            << 100 * eval_ref.centre_rmse_fraction << " % and " << 100 * eval_mov.centre_rmse_fraction << " %\n"
            << report.at("tree")[0].dump(2) << "\n"
            << report.at("joint_bundle_adjustment").dump(2) << "\n";
  // The merged model: after the joint BA both tracks' cameras have moved (the reference's too), so the
  // registration of B onto A is measured inside the merged model — each track's part aligned to its own truth
  // (one world): a perfect merge needs one and the same similarity for both parts.
  const core::Reconstruction merged_model = io::ReadColmapText(root / "AB/sparse");
  const auto [merged_ref_part, merged_mov_part] = align::SplitByNamePrefix(merged_model, mov.string() + "-");
  const auto in_merged_ref =
      sfm::EvaluateSparse(merged_ref_part, sfm::LoadTruth((root / ("synth_" + ref.string()) / "truth").string()));
  const auto in_merged_mov =
      sfm::EvaluateSparse(merged_mov_part, sfm::LoadTruth((root / ("synth_" + mov.string()) / "truth").string()));
  ASSERT_EQ(in_merged_ref.num_matched, eval_ref.num_matched);
  ASSERT_EQ(in_merged_mov.num_matched, eval_mov.num_matched);
  const sfm::SimilarityError merged_err =
      sfm::CompareSimilarityToTruth(core::Sim3{}, in_merged_ref, in_merged_mov, centroid);
  std::cout << "in the merged model, B registered onto A vs truth: rotation " << merged_err.rotation_deg
            << " deg, scale " << 100 * merged_err.scale << " %, translation " << 100 * merged_err.translation_fraction
            << " %\n";
  // The merged model must meet the bounds; the coarse similarity alone (cross-track correspondences +
  // refit) measured 0.007°, 0.125%, 0.008% — bounded at twice.
  EXPECT_LE(merged_err.rotation_deg, 0.05);
  EXPECT_LE(merged_err.scale, 0.001);
  EXPECT_LE(merged_err.translation_fraction, 0.001);
  EXPECT_LE(rotation_deg, 0.1);
  EXPECT_LE(scale_err, 0.002);
  EXPECT_LE(translation_frac, 0.002);
  EXPECT_GE(report.at("tree")[0].at("overlap_fraction").get<double>(), 0.5);

  const core::Reconstruction merged = io::ReadColmapText(root / "AB/sparse");
  EXPECT_EQ(merged.images.size(), rec_ref.images.size() + rec_mov.images.size());
  const auto& joint = report.at("joint_bundle_adjustment");
  EXPECT_EQ(merged.points.size(),
            rec_ref.points.size() + rec_mov.points.size() - joint.at("links_fused").get<size_t>());
  EXPECT_GE(joint.at("links_fused").get<size_t>(), 100u);
  EXPECT_LE(joint.at("reprojection_rms_after_px").get<double>(), 1.0);
  EXPECT_TRUE(fs::exists(root / "AB/frames/frames.json"));

  // With dense clouds (small working size to keep CI short), the merge runs multi-view stereo again over both
  // tracks' views. Its cloud must be no less accurate than the union of the two clouds (`--union`, which mixes
  // the worse track in wherever both see the surface) and as complete as the better track. (Its median
  // against each single track's depends on how much surface each sees alone: bench/align_bench measures it.)
  for (const std::string t : {"A", "B"}) {
    Cli("-q dense --max-size 240 --no-previews " + (root / t).string());
    Cli("-q evaluate-dense " + (root / t).string() + " --truth " + (root / ("synth_" + t)).string());
  }
  for (const std::string merge : {"ABd", "ABu"}) {
    fs::remove_all(root / merge);
    Cli(std::string("-q align ") + (merge == "ABu" ? "--union " : "") + (root / "A").string() + " " +
        (root / "B").string() + " -o " + (root / merge).string());
    Cli("-q evaluate-dense " + (root / merge).string() + " --truth " + (root / ("synth_" + ref.string())).string());
  }
  const auto dense_report = core::ReadJson(root / "ABd/report/align.json").at("dense");
  EXPECT_EQ(dense_report.at("method").get<std::string>(), "recomputed over every track's views");
  EXPECT_EQ(dense_report.at("max_size").get<int>(), 240);
  EXPECT_EQ(core::ReadJson(root / "ABu/report/align.json").at("dense").at("method").get<std::string>(), "union");
  auto figures = [&](const fs::path& ws) {
    const auto j = core::ReadJson(ws / "report/dense_eval.json");
    return std::make_pair(j.at("accuracy_in_region").at("median_percent_of_length").get<double>(),
                          j.at("completeness").at("fraction").get<double>());
  };
  const auto [median_a, complete_a] = figures(root / "A");
  const auto [median_b, complete_b] = figures(root / "B");
  const auto [median_ab, complete_ab] = figures(root / "ABd");
  const auto [median_union, complete_union] = figures(root / "ABu");
  std::cout << "dense median error in the region % of H / completeness: A " << median_a << " / " << complete_a << ", B "
            << median_b << " / " << complete_b << ", union " << median_union << " / " << complete_union
            << ", recomputed " << median_ab << " / " << complete_ab << "\n";
  // Accuracy and completeness both over the modelled region (the backdrop ring, where grazing far ground is kept
  // with its σ, left out), so each cloud's median is read on the surface its completeness counts. Measured: A
  // 0.163% / 40.6%, B 0.143% / 17.7%, union 0.159% / 42.9%, recomputed 0.165% / 43.6%: the recomputed cloud also
  // holds ground that B's low views see at grazing angles, less accurate than the rest, so its median sits 3.7%
  // above the union's and 1.3% above A's. Runs at 240 px differ between machines, so both accuracy bounds allow
  // 6%: they fail when recomputing loses accuracy, not on the run-to-run spread. Half a point of completeness
  // likewise. (Full-size figures: bench/align_bench.)
  EXPECT_LE(median_ab, 1.06 * median_union);
  EXPECT_LE(median_ab, 1.06 * std::max(median_a, median_b));
  EXPECT_GE(complete_ab, std::max(complete_a, complete_b) - 0.005);
}

}  // namespace
}  // namespace fmv3d::test
