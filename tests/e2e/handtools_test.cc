// End to end, the operator's hand tools as the console's pages save them (docs/manual-inputs.md), on one
// synthetic orbit (24 frames, 960x540, no telemetry) whose frames 8 and 9 are degraded by heavy motion blur
// (`synth --degrade 8,9:blur`):
//   1. automatic matching leaves frames 8 and 9 out;
//   2. GCPs: 5 control points and 1 check point clicked at their true projections with ±1 px noise, in WGS84 /
//      UTM 32N (`truth-projections --format gcp`), and no telemetry → `georef` (similarity, then bundle adjustment
//      with the GCP constraints) places every registered camera within 0.1% of the extent (the true centres'
//      diameter) of its true position in absolute coordinates, and reports each GCP's residual and the check
//      point's (clicks within ±1 px, uniform per coordinate; Gaussian σ = 1 px clicks reach 0.102% on two of six
//      noise seeds of this flight: bench/results/handtools3.md);
//   3. tie points at the true projections of 12 scene points seen by frames 8 and 9 and at least two other frames
//      (`truth-projections --format tiepoints`) → `match` + `sparse` register both frames through them, with
//      camera centre error ≤ 0.1% of the extent after the similarity alignment to the truth. That `match` re-run
//      reads the automatic pairs back (match_cache.h: features and options unchanged) and adds the tie points.
#include <gtest/gtest.h>

#include <limits>

#include "fmv3d/core/files.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/sfm/evaluation.h"
#include "test_util.h"

namespace fmv3d::test {
namespace {

void Cli(const std::string& args) {
  const auto r = RunCli(args);
  ASSERT_EQ(r.exit_code, 0) << "fmv3d " << args << "\n" << r.err;
}

bool LeftOut(const nlohmann::json& sparse, const std::string& name) {
  for (const auto& l : sparse.at("left_out"))
    if (l.at("image") == name) return true;
  return false;
}

double Extent(const core::Reconstruction& truth) {
  std::vector<Eigen::Vector3d> c;
  for (const auto& [id, im] : truth.images) c.push_back(im.pose.Centre());
  double e = 0;
  for (size_t i = 0; i < c.size(); ++i)
    for (size_t j = i + 1; j < c.size(); ++j) e = std::max(e, (c[i] - c[j]).norm());
  return e;
}

// Largest distance of geo/sparse_enu's camera centres from the true ones in absolute terms (georef ENU → WGS84 →
// the truth's ENU at `origin`, no alignment); prints it with the RMS.
double WorstAbsoluteCentreError(const fs::path& ws, const core::Reconstruction& truth, const geo::GeoPoint& origin,
                                double extent, const std::string& what) {
  const auto georef = core::ReadJson(ws / "geo/georef.json");
  const geo::GeoPoint o{georef["origin"]["lat"].get<double>(), georef["origin"]["lon"].get<double>(),
                        georef["origin"]["alt"].get<double>()};
  const geo::LocalFrame georef_frame(o), truth_frame(origin);
  const core::Reconstruction enu = io::ReadColmapText(ws / "geo/sparse_enu");
  double worst = 0, sse = 0;
  for (const auto& [id, im] : enu.images) {
    const core::Image* t = truth.FindImageByName(im.name);
    if (!t) return std::numeric_limits<double>::infinity();
    const Eigen::Vector3d c = truth_frame.ToEnu(georef_frame.ToGeodetic(im.pose.Centre()));
    const double e = (c - t->pose.Centre()).norm();
    worst = std::max(worst, e);
    sse += e * e;
  }
  std::cout << "GCP georef (" << what << "): camera centres vs truth, absolute: max " << worst
            << " m = " << 100 * worst / extent << "% of the extent " << extent << " m, RMS "
            << std::sqrt(sse / enu.images.size()) << " m; adjustment " << georef["gcps"]["adjustment"].dump() << "\n";
  return worst;
}

TEST(E2eHandTools, DegradedFramesTiePointsAndGcps) {
  TempDir dir("fmv3d-e2e-handtools");
  const std::string synth = (dir / "synth").string(), ws = (dir / "ws").string();
  Cli("-q synth --scene town --path orbit --frames 24 --size 960x540 --seed 7 --degrade 8,9:blur -o " + synth);
  Cli("-q frames " + synth + "/frames -o " + ws);
  Cli("-q features " + ws);
  Cli("-q match " + ws);
  Cli("-q sparse " + ws);
  const core::Reconstruction truth = io::ReadColmapText(dir / "synth/truth");
  const double extent = Extent(truth);
  const std::string f8 = "flight-000008.png", f9 = "flight-000009.png";
  {
    const auto sparse = core::ReadJson(dir / "ws/report/sparse.json");
    EXPECT_TRUE(LeftOut(sparse, f8)) << sparse.at("left_out").dump();
    EXPECT_TRUE(LeftOut(sparse, f9)) << sparse.at("left_out").dump();
    EXPECT_EQ(sparse.at("registered_images").get<int>(), 22);
  }

  // --- GCPs, no telemetry.
  const geo::GeoPoint origin{46.95, 7.44, 540};
  Cli("truth-projections " + synth + " --ws " + ws +
      " --points 6 --check 1 --noise-max 1 --seed 3 --format gcp --crs 'WGS84 UTM 32N' --origin 46.95,7.44,540 -o " +
      ws + "/manual/gcp_list.txt");
  Cli("manual check " + ws);
  Cli("-q georef " + ws);
  {
    const auto georef = core::ReadJson(dir / "ws/geo/georef.json");
    std::cout << georef.at("gcps").dump(2) << "\n";
    EXPECT_EQ(georef.at("source"), "gcp");
    EXPECT_EQ(georef.at("vertical_datum"), "WGS84 ellipsoid");
    EXPECT_EQ(georef.at("gcps").at("control_points_used").get<int>(), 5);
    EXPECT_EQ(georef.at("gcps").at("check_points_used").get<int>(), 1);
    ASSERT_TRUE(georef.at("gcps").at("check_rms_m").is_number());
    for (const auto& p : georef.at("gcps").at("points")) EXPECT_TRUE(p.contains("residual_m")) << p.dump();
    // The check point's residual: the triangulation of σ = 1 px clicks at ~300 m (a few decimetres) and the fit.
    EXPECT_LT(georef.at("gcps").at("check_rms_m").get<double>(), 0.002 * extent);
    EXPECT_TRUE(georef.at("gcps").at("adjustment").at("applied").get<bool>());
    EXPECT_EQ(io::ReadColmapText(dir / "ws/geo/sparse_enu").images.size(), 22u);
    EXPECT_LE(WorstAbsoluteCentreError(dir / "ws", truth, origin, extent, "uniform ±1 px clicks"), 0.001 * extent);
  }

  // --- Tie points register the degraded frames.
  Cli("truth-projections " + synth + " --ws " + ws + " --in " + f8 + "," + f9 +
      " --points 12 --min-frames 4 --format tiepoints -o " + ws + "/manual/tiepoints.json");
  Cli("manual check " + ws);
  Cli("-q match " + ws);
  const auto matches = core::ReadJson(dir / "ws/matches/matches.json");
  EXPECT_TRUE(matches.at("manual").at("used").get<bool>());
  EXPECT_EQ(matches.at("manual").at("tie_points").get<int>(), 12);
  EXPECT_EQ(matches.at("pairs_reused"), matches.at("pairs_tried"));
  Cli("-q sparse " + ws);
  const auto sparse = core::ReadJson(dir / "ws/report/sparse.json");
  std::cout << sparse.at("manual").dump(2) << "\n";
  EXPECT_FALSE(LeftOut(sparse, f8));
  EXPECT_FALSE(LeftOut(sparse, f9));
  const core::Reconstruction model = io::ReadColmapText(dir / "ws/sparse");
  const auto eval = sfm::EvaluateSparse(model, truth);
  EXPECT_EQ(eval.num_matched, 24);
  for (const std::string& name : {f8, f9}) {
    const core::Image* im = model.FindImageByName(name);
    ASSERT_NE(im, nullptr) << name << " not registered";
    const double e = (eval.alignment.Apply(im->pose.Centre()) - truth.FindImageByName(name)->pose.Centre()).norm();
    std::cout << name << ": camera centre error " << e << " m = " << 100 * e / eval.extent << "% of the extent\n";
    EXPECT_LE(e, 0.001 * eval.extent) << name;
  }
  std::cout << "all frames: centre RMSE " << 100 * eval.centre_rmse_fraction << "% of the extent, max "
            << 100 * eval.max_centre_error_fraction << "%\n";
  EXPECT_LE(eval.max_centre_error_fraction, 0.001);
}

}  // namespace
}  // namespace fmv3d::test
