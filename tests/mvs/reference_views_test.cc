// SelectReferenceViews (the reference-view cover of `fmv3d dense --reference-coverage`): a video-like orbit whose
// SfM tracks are broken into 2-view pieces, as sequential matching leaves many of them. A cover driven by the
// tracks alone would need every view; the projected-visibility cover needs a fraction of them and still gives
// each point the requested number of reference views that see it from its side.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/mvs/view.h"
#include "fmv3d/mvs/view_selection.h"

namespace fmv3d::mvs {
namespace {

// 72 frames on a circle of radius 80 at 40 m height looking at the origin; points on the 4 walls of a
// 20 x 20 x 20 m box, each observed only by two consecutive frames that see its wall from the front.
core::Reconstruction VideoOrbit(int frames = 72) {
  core::Reconstruction rec;
  rec.cameras[1] = core::Camera::Pinhole(640, 360, 500);
  for (int i = 0; i < frames; ++i) {
    core::Image im;
    im.id = static_cast<uint32_t>(i + 1);
    im.camera_id = 1;
    im.name = "f" + std::to_string(i) + ".png";
    const double a = 2 * M_PI * i / frames;
    im.pose = core::Pose::LookAt({80 * std::cos(a), 80 * std::sin(a), 40}, {0, 0, 10});
    rec.images[im.id] = im;
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-10, 10), h(0, 20);
  std::uniform_int_distribution<int> pick(0, frames - 1);
  uint64_t next = 1;
  while (rec.points.size() < 4000) {
    const int i = pick(rng), j = (i + 1) % frames;
    const Eigen::Vector3d ci = rec.images[i + 1].pose.Centre();
    // A point on the wall that faces frame i most directly.
    Eigen::Vector3d n = Eigen::Vector3d(ci.x(), ci.y(), 0);
    Eigen::Vector3d X;
    if (std::abs(n.x()) > std::abs(n.y()))
      X = {n.x() > 0 ? 10.0 : -10.0, u(rng), h(rng)};
    else
      X = {u(rng), n.y() > 0 ? 10.0 : -10.0, h(rng)};
    core::Point3D p;
    p.id = next++;
    p.xyz = X;
    p.track = {{static_cast<uint32_t>(i + 1), 0}, {static_cast<uint32_t>(j + 1), 0}};
    rec.points[p.id] = p;
  }
  return rec;
}

std::map<uint32_t, ViewGeometry> Geometries(const core::Reconstruction& rec) {
  std::map<uint32_t, ViewGeometry> g;
  for (const auto& [id, im] : rec.images) g[id] = MakeViewGeometry(rec, id, 0);
  return g;
}

std::vector<uint32_t> AllIds(const core::Reconstruction& rec) {
  std::vector<uint32_t> ids;
  for (const auto& [id, im] : rec.images) ids.push_back(id);
  return ids;
}

// Chosen views that see X from the front of its wall (outward normal n) and inside the image.
int FrontViews(const Eigen::Vector3d& X, const Eigen::Vector3d& n, const std::vector<uint32_t>& chosen,
               const std::map<uint32_t, ViewGeometry>& geoms) {
  int k = 0;
  for (uint32_t id : chosen) {
    const ViewGeometry& g = geoms.at(id);
    Eigen::Vector2d uv;
    if ((g.Centre() - X).dot(n) > 0 && g.Project(X, &uv) && uv.x() >= 0 && uv.y() >= 0 && uv.x() < g.width &&
        uv.y() < g.height)
      ++k;
  }
  return k;
}

TEST(ReferenceViews, CoverNeedsAFractionOfAVideoOrbitAndSeesEveryPointEnoughTimes) {
  const core::Reconstruction rec = VideoOrbit();
  const auto geoms = Geometries(rec);
  ReferenceCoverOptions opt;
  opt.coverage = 4;
  const auto chosen = SelectReferenceViews(rec, geoms, AllIds(rec), opt);
  // Every frame sees two walls over ~90° of the orbit; 4 covering views per wall point need far fewer than 72.
  EXPECT_LE(chosen.size(), 72u / 2);
  EXPECT_GE(chosen.size(), 8u);
  EXPECT_TRUE(std::is_sorted(chosen.begin(), chosen.end()));
  int enough = 0;
  for (const auto& [pid, p] : rec.points) {
    const Eigen::Vector3d& X = p.xyz;
    const Eigen::Vector3d n =
        std::abs(std::abs(X.x()) - 10) < 1e-9 ? Eigen::Vector3d(X.x() / 10, 0, 0) : Eigen::Vector3d(0, X.y() / 10, 0);
    enough += FrontViews(X, n, chosen, geoms) >= 4 ? 1 : 0;
  }
  EXPECT_GE(enough, static_cast<int>(0.95 * rec.points.size())) << "of " << rec.points.size();
  // The tracks alone (a vanishing cone admits no other view) need nearly every frame: the reason for the
  // projected visibility.
  ReferenceCoverOptions tracks_only = opt;
  tracks_only.cone_deg = 1e-6;
  EXPECT_GE(SelectReferenceViews(rec, geoms, AllIds(rec), tracks_only).size(), 64u);
  std::printf("cover of 4: %zu of 72 views; from the tracks alone: %zu\n", chosen.size(),
              SelectReferenceViews(rec, geoms, AllIds(rec), tracks_only).size());
}

TEST(ReferenceViews, HigherCoverageChoosesMoreViews) {
  const core::Reconstruction rec = VideoOrbit();
  const auto geoms = Geometries(rec);
  ReferenceCoverOptions lo, hi;
  lo.coverage = 2;
  hi.coverage = 8;
  EXPECT_LT(SelectReferenceViews(rec, geoms, AllIds(rec), lo).size(),
            SelectReferenceViews(rec, geoms, AllIds(rec), hi).size());
}

TEST(ReferenceViews, EveryViewWhenOffOrWithoutSparsePoints) {
  core::Reconstruction rec = VideoOrbit(24);
  const auto geoms = Geometries(rec);
  ReferenceCoverOptions off;
  EXPECT_EQ(SelectReferenceViews(rec, geoms, AllIds(rec), off).size(), 24u);
  rec.points.clear();  // e.g. ground-truth cameras only: nothing to cover, every view is a reference
  ReferenceCoverOptions on;
  on.coverage = 4;
  EXPECT_EQ(SelectReferenceViews(rec, geoms, AllIds(rec), on).size(), 24u);
}

TEST(ReferenceViews, OnlyCandidatesAreChosen) {
  const core::Reconstruction rec = VideoOrbit();
  const auto geoms = Geometries(rec);
  std::vector<uint32_t> even;
  for (uint32_t id = 2; id <= 72; id += 2) even.push_back(id);
  ReferenceCoverOptions opt;
  opt.coverage = 3;
  for (uint32_t id : SelectReferenceViews(rec, geoms, even, opt)) EXPECT_EQ(id % 2, 0u);
}

}  // namespace
}  // namespace fmv3d::mvs
