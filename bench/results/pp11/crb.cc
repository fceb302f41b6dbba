// What the data allow: the posterior σ of the intrinsics from the BA covariance evaluated at the TRUE cameras and
// points, against the σ our BA reports at its own solution (bench/results/pp11.md §1).
//
//   crb MODEL TRUTH [draws [sigma]]
// MODEL: a sparse model (COLMAP text) whose tracks are used, or "truth" for truth/points3D's tracks (synth's
// depth-tested surface samples). TRUTH: the flight's truth/ (COLMAP text).
// The tracks are re-triangulated with the true cameras (pose and intrinsics by image name). Then, for each free set
// (f, u0, v0, k1, k2 as the final BA; f, u0, v0; u0, v0 with the focal held):
//  - real: the matched keypoints at the truth (Cauchy 1 px as the BA, σ² from their own residuals);
//  - ideal: the true projections + Gaussian noise of the measured core σ (plain squares): the Cramér–Rao bound;
//  - ours: the model's own covariance at its solution (MODEL only).
// sigma: the ideal observations' noise (default: the core σ of the real keypoints at the truth; needed with "truth").
// draws > 0: as many Monte Carlo fits (BA from the truth, Cauchy 1 px, f/pp/k1/k2 free) on ideal observations
// with fresh noise: the scatter an efficient estimator reaches.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <string>

#include "fmv3d/core/camera.h"
#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/sfm/bundle_adjustment.h"
#include "fmv3d/sfm/evaluation.h"

using namespace fmv3d;
using Cov = Eigen::Matrix<double, core::kNumIntrinsics, core::kNumIntrinsics>;

namespace {

struct FreeSet {
  const char* name;
  bool f, pp, k;
};
const FreeSet kSets[] = {
    {"f,pp,k1,k2", true, true, true}, {"f,pp", true, true, false}, {"pp (f held)", false, true, false}};

sfm::BundleAdjustmentOptions Options(const FreeSet& s, bool robust) {
  sfm::BundleAdjustmentOptions o;
  o.refine_focal = s.f;
  o.refine_principal_point = s.pp;
  o.refine_k1 = o.refine_k2 = s.k;
  o.loss = robust ? sfm::BundleAdjustmentOptions::Loss::kCauchy : sfm::BundleAdjustmentOptions::Loss::kTrivial;
  return o;
}

void Print(const char* what, const FreeSet& s, const sfm::BundleAdjustmentSummary& r) {
  if (r.intrinsics_covariance.empty()) {
    std::printf("  %-28s %-12s rank-deficient (rms %.4f)\n", what, s.name, r.final_rms_px);
    return;
  }
  const Cov& C = r.intrinsics_covariance.begin()->second;
  auto sd = [&](int i) { return std::sqrt(std::max(0.0, C(i, i))); };
  const double corr = sd(core::kF) > 0 ? C(core::kF, core::kV0) / (sd(core::kF) * sd(core::kV0)) : 0;
  std::printf("  %-28s %-12s sigma f %.3f u0 %.3f v0 %.3f  corr(f,v0) %+.3f  (rms %.4f, %d obs)\n", what, s.name,
              sd(core::kF), sd(core::kU0), sd(core::kV0), corr, r.final_rms_px, r.num_residuals);
}

// The model's tracks on the true cameras: intrinsics and poses of the truth (by image name), points re-triangulated.
core::Reconstruction OnTruth(const core::Reconstruction& model, const core::Reconstruction& truth) {
  std::map<std::string, const core::Image*> by_name;
  for (const auto& [id, im] : truth.images) by_name[im.name] = &im;
  core::Reconstruction r = model;
  const core::Camera tc = truth.cameras.begin()->second;
  for (auto& [cid, c] : r.cameras) {
    const uint32_t id = c.id;
    c = tc;
    c.id = id;
  }
  for (auto& [id, im] : r.images) im.pose = by_name.at(im.name)->pose;
  for (auto it = r.points.begin(); it != r.points.end();) {
    std::vector<core::Pose> poses;
    std::vector<Eigen::Vector2d> xn;
    for (const auto& e : it->second.track) {
      const auto& im = r.images.at(e.image_id);
      poses.push_back(im.pose);
      xn.push_back(r.cameras.at(im.camera_id).Unproject(im.points2d[e.point2d_idx]).head<2>());
    }
    Eigen::Vector3d X;
    bool ok = poses.size() >= 2 && geometry::TriangulateDLT(poses, xn, &X);
    if (ok) geometry::RefinePoint(poses, xn, &X, 10);
    for (const auto& p : poses) ok = ok && geometry::HasPositiveDepth(p, X);
    if (!ok) {
      for (const auto& e : it->second.track) r.images.at(e.image_id).point3d_ids[e.point2d_idx] = core::kNoPoint3D;
      it = r.points.erase(it);
      continue;
    }
    it->second.xyz = X;
    ++it;
  }
  return r;
}

// Observations replaced by the true projections plus N(0, σ²) per coordinate.
void Idealise(core::Reconstruction* r, double sigma, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, sigma);
  for (const auto& [pid, p] : r->points)
    for (const auto& e : p.track) {
      auto& im = r->images.at(e.image_id);
      im.points2d[e.point2d_idx] =
          r->cameras.at(im.camera_id).Project(im.pose.Transform(p.xyz)) + Eigen::Vector2d{g(rng), g(rng)};
    }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: crb MODEL|truth TRUTH [draws [sigma]]\n");
    return 2;
  }
  const std::string model_dir = argv[1];
  const core::Reconstruction truth = sfm::LoadTruth(argv[2]);
  const int draws = argc > 3 ? std::atoi(argv[3]) : 0;
  const double given_sigma = argc > 4 ? std::atof(argv[4]) : 0;
  const bool own = model_dir != "truth";
  const core::Reconstruction model = own ? io::ReadColmapText(model_dir) : truth;
  const core::Camera& tc = truth.cameras.begin()->second;
  std::printf("truth: f %.3f pp %.3f %.3f; %zu images, %zu points\n", tc.f, tc.u0, tc.v0, model.images.size(),
              model.points.size());
  if (own) {
    const core::Camera& mc = model.cameras.begin()->second;
    std::printf("model: f %.3f (%+.3f) pp %.3f %.3f (%+.3f %+.3f) k1 %.5f k2 %.5f\n", mc.f, mc.f - tc.f, mc.u0, mc.v0,
                mc.u0 - tc.u0, mc.v0 - tc.v0, mc.k1, mc.k2);
  }
  core::Reconstruction at_truth = OnTruth(model, truth);
  std::vector<double> errs;
  for (const auto& [pid, p] : at_truth.points)
    for (const auto& e : p.track) errs.push_back(sfm::ObservationError(at_truth, e.image_id, e.point2d_idx, p.xyz));
  std::vector<double> sorted = errs;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  double ss = 0;
  for (double e : errs) ss += e * e;
  const double core_sigma = given_sigma > 0 ? given_sigma : sorted[sorted.size() / 2] / std::sqrt(2 * std::log(2.0));
  const double rms_axis = std::sqrt(ss / errs.size() / 2);
  std::printf(
      "at the truth: %zu points, %zu observations; keypoint noise: core sigma %.4f px per axis, rms %.4f px "
      "per axis\n",
      at_truth.points.size(), errs.size(), core_sigma, rms_axis);
  for (const FreeSet& s : kSets) {
    if (own) {
      Print("ours (model, Cauchy 1 px)", s, sfm::IntrinsicsCovarianceAt(model, {}, Options(s, true)));
      Print("real keypoints at truth", s, sfm::IntrinsicsCovarianceAt(at_truth, {}, Options(s, true)));
      Print("real keypoints, squares", s, sfm::IntrinsicsCovarianceAt(at_truth, {}, Options(s, false)));
    }
    for (double sigma : {core_sigma, rms_axis}) {
      if (!own && sigma != core_sigma) continue;
      core::Reconstruction ideal = at_truth;
      Idealise(&ideal, sigma, 1);
      char what[64];
      std::snprintf(what, sizeof what, "ideal + N(0, %.3f)", sigma);
      Print(what, s, sfm::IntrinsicsCovarianceAt(ideal, {}, Options(s, false)));
    }
  }
  if (draws > 0) {
    std::vector<double> dv, du, df;
    for (int k = 0; k < draws; ++k) {
      core::Reconstruction ideal = at_truth;
      Idealise(&ideal, core_sigma, 100 + k);
      auto o = Options(kSets[0], true);
      o.function_tolerance = 1e-10;
      o.max_iterations = 200;
      o.initial_trust_region_radius = 1e8;
      sfm::BundleAdjust(&ideal, {}, o);
      const core::Camera& c = ideal.cameras.begin()->second;
      df.push_back(c.f - tc.f);
      du.push_back(c.u0 - tc.u0);
      dv.push_back(c.v0 - tc.v0);
      std::printf("  draw %d: df %+.3f du0 %+.3f dv0 %+.3f\n", k, df.back(), du.back(), dv.back());
    }
    auto rms = [](const std::vector<double>& v) {
      double s = 0;
      for (double x : v) s += x * x;
      return std::sqrt(s / v.size());
    };
    std::printf("Monte Carlo (%d draws, sigma %.4f): rms error f %.3f u0 %.3f v0 %.3f px\n", draws, core_sigma, rms(df),
                rms(du), rms(dv));
  }
}
