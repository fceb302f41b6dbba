// Scaled ICP and global registration against known similarities (B is A's point set under a random
// similarity — scale 0.2–5, any rotation — plus noise; recovered to 1e-4 relative).
#include "fmv3d/align/icp.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "fmv3d/align/global_registration.h"
#include "fmv3d/core/error.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/synth/scene.h"

namespace fmv3d::align {
namespace {

// A CAD-like test object: the synthetic gable-roofed building (20 x 12 m, ridge 30 m) with a flat-roofed
// annex in one corner (so that no rotation maps the shape onto itself) on a 50 x 36 m ground slab, sampled
// every `spacing` metres with the faces' outward normals.
io::OrientedPointCloud BuildingCloud(double spacing) {
  io::TexturedMesh mesh = synth::MakeBuilding(synth::BuildingSpec{}, 0);
  synth::BuildingSpec annex;
  annex.width = 8;
  annex.depth = 6;
  annex.eave_height = annex.ridge_height = 9;
  annex.base = Eigen::Vector3d(14, 7, 0);
  mesh.Append(synth::MakeBuilding(annex, 0));
  io::TexturedMesh ground;
  ground.vertices = {{-25, -18, 0}, {25, -18, 0}, {25, 18, 0}, {-25, 18, 0}};
  io::Face f1, f2;
  f1.v[0] = 0, f1.v[1] = 1, f1.v[2] = 2;
  f2.v[0] = 0, f2.v[1] = 2, f2.v[2] = 3;
  ground.faces = {f1, f2};
  mesh.Append(ground);
  const geometry::MeshDistance md(mesh);
  std::vector<int> faces;
  io::OrientedPointCloud cloud;
  cloud.positions = md.SampleSurface(spacing, &faces, 3);
  for (int f : faces) cloud.normals.push_back(md.Normal(f).cast<float>());
  return cloud;
}

core::Sim3 RandomSim3(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g(0, 1);
  core::Sim3 s;
  s.s = std::exp(std::log(0.2) + u(rng) * (std::log(5.0) - std::log(0.2)));  // log-uniform in [0.2, 5]
  s.q = Eigen::Quaterniond{g(rng), g(rng), g(rng), g(rng)}.normalized();     // uniform on SO(3)
  s.t = Eigen::Vector3d{g(rng), g(rng), g(rng)} * 100;
  return s;
}

// Largest displacement of any point of `cloud` by `e` (identity when perfect), relative to the cloud's radius.
double RelativeError(const core::Sim3& e, const io::OrientedPointCloud& cloud) {
  const double r = RmsRadius(cloud.positions);
  double worst = 0;
  for (const auto& p : cloud.positions) worst = std::max(worst, (e.Apply(p) - p).norm());
  return worst / r;
}

io::OrientedPointCloud Apply(const core::Sim3& s, const io::OrientedPointCloud& in, double noise, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, noise);
  io::OrientedPointCloud out;
  for (const auto& p : in.positions) out.positions.push_back(s.Apply(p) + Eigen::Vector3d{g(rng), g(rng), g(rng)});
  return out;  // no normals: the source's are estimated by PCA, as for a raw scan
}

TEST(ScaledIcp, RecoversRandomSimilarityFromGlobalRegistration) {
  const io::OrientedPointCloud a = BuildingCloud(0.45);
  ASSERT_GT(a.size(), 15000u);
  const IcpTarget target(a);
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 3; ++trial) {
    const core::Sim3 truth = RandomSim3(rng);
    // Noise: 2 mm on a 30 m building (before scaling). The recovered similarity's error grows linearly with
    // it (measured on this object: 1e-5 at 1 mm, 1e-4 at 1 cm; exact to 1e-15 without noise).
    const io::OrientedPointCloud b = Apply(truth, a, 0.002 * truth.s, 100 + trial);
    GlobalRegistrationOptions go;
    const GlobalRegistrationResult coarse = GlobalRegistration(b, a, go);
    const core::Sim3 coarse_err = ComposeSim3(coarse.transform, truth);
    IcpOptions o;
    const IcpResult fine = ScaledIcp(b, target, coarse.transform, o);
    const core::Sim3 e = ComposeSim3(fine.transform, truth);  // identity when B → A undoes A → B
    SCOPED_TRACE("trial " + std::to_string(trial) + " scale " + std::to_string(truth.s) + " coarse via " +
                 coarse.method + " err " + std::to_string(RelativeError(coarse_err, a)));
    EXPECT_TRUE(fine.converged);
    EXPECT_LT(std::abs(e.s - 1), 1e-4);
    EXPECT_LT(core::RotationAngle(e.q, Eigen::Quaterniond::Identity()), 1e-4);
    EXPECT_LT(RelativeError(e, a), 1e-4);
    EXPECT_GT(fine.fitness, 0.85);
    EXPECT_LT(fine.rmse, fine.initial_rmse);
  }
}

TEST(ScaledIcp, PartialOverlapAndOutliersAreTrimmed) {
  const io::OrientedPointCloud a = BuildingCloud(0.45);
  const IcpTarget target(a);
  std::mt19937_64 rng(5);
  core::Sim3 truth = RandomSim3(rng);
  // B sees only the part of A with x < 5 (about 60%), plus 10% gross outliers in its bounding box.
  io::OrientedPointCloud part;
  for (const auto& p : a.positions)
    if (p.x() < 5) part.positions.push_back(p);
  io::OrientedPointCloud b = Apply(truth, part, 0.01 * truth.s, 9);
  const Eigen::AlignedBox3d box = b.Bounds();
  std::uniform_real_distribution<double> u(0, 1);
  const size_t outliers = b.size() / 10;
  for (size_t i = 0; i < outliers; ++i)
    b.positions.push_back(box.min() + box.diagonal().cwiseProduct(Eigen::Vector3d{u(rng), u(rng), u(rng)}));
  // Start 5° and 5% off the truth.
  core::Sim3 perturb;
  perturb.s = 1.05;
  perturb.q = Eigen::AngleAxisd(5 * M_PI / 180, Eigen::Vector3d(1, 2, 3).normalized());
  perturb.t = Eigen::Vector3d(1, -1, 0.5);
  const core::Sim3 start = ComposeSim3(perturb, truth.Inverse());
  IcpOptions o;
  o.trim_fraction = 0.8;
  const IcpResult r = ScaledIcp(b, target, start, o);
  const core::Sim3 e = ComposeSim3(r.transform, truth);
  EXPECT_LT(std::abs(e.s - 1), 1e-3);
  EXPECT_LT(core::RotationAngle(e.q, Eigen::Quaterniond::Identity()), 1e-3);
  EXPECT_LT(RelativeError(e, part), 1e-3);
}

// A flat textured patch: geometry alone cannot see a slide along the plane; the colour term can.
TEST(ScaledIcp, ColourTermFixesSlideAlongAPlane) {
  io::OrientedPointCloud plane;
  const double step = 0.1;
  for (int i = 0; i < 150; ++i)
    for (int j = 0; j < 150; ++j) {
      const double x = i * step, y = j * step;
      plane.positions.push_back({x, y, 0});
      plane.normals.push_back(Eigen::Vector3f::UnitZ());
      const double v = 0.5 + 0.4 * std::sin(x * 1.3) * std::cos(y * 0.9 + 0.5);
      const uint8_t c = static_cast<uint8_t>(std::lround(255 * v));
      plane.colors.push_back(io::Rgb8(c, c, c));
    }
  const IcpTarget target(plane, 20, /*with_colour=*/true);
  core::Sim3 start;
  start.t = Eigen::Vector3d(0.25, -0.2, 0.05);  // source = target; the start slides it 32 cm along the plane
  IcpOptions o;
  o.estimate_scale = false;
  o.trim_fraction = 0.7;  // the slid border has no counterpart
  const IcpResult geometric = ScaledIcp(plane, target, start, o);
  o.colour_weight = 0.3;
  const IcpResult coloured = ScaledIcp(plane, target, start, o);
  EXPECT_GT(geometric.transform.t.head<2>().norm(), 0.1) << "geometry alone cannot undo a slide";
  EXPECT_NEAR(geometric.transform.t.z(), 0, 1e-6);
  EXPECT_LT(coloured.transform.t.norm(), 0.01) << coloured.transform.t.transpose();
}

TEST(ScaledIcp, ReportsNoOverlapAndBadOptions) {
  const io::OrientedPointCloud a = BuildingCloud(1.0);
  const IcpTarget target(a);
  core::Sim3 far;
  far.t = Eigen::Vector3d(1e4, 0, 0);
  IcpOptions o;
  o.max_correspondence_distance = 1.0;
  EXPECT_THROW(ScaledIcp(a, target, far, o), Error);
  o = IcpOptions();
  o.trim_fraction = 0;
  EXPECT_THROW(o.Check(), Error);
  o = IcpOptions();
  o.colour_weight = 1;
  EXPECT_THROW(o.Check(), Error);
  EXPECT_THROW(ScaledIcp(io::OrientedPointCloud(), target, core::Sim3(), IcpOptions()), Error);
  EXPECT_THROW(ParseRobustLoss("tukey"), Error);
}

}  // namespace
}  // namespace fmv3d::align
