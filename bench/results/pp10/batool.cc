// Experiments on a finished sparse model: where does bundle adjustment put the principal point?
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include "fmv3d/io/colmap_model.h"
#include "fmv3d/sfm/bundle_adjustment.h"
using namespace fmv3d;
int main(int argc, char** argv) {
  auto rec = io::ReadColmapText(argv[1]);
  const std::string mode = argv[2];
  const double tu = std::stod(argv[3]), tv = std::stod(argv[4]);
  const double noise = argc > 5 ? std::stod(argv[5]) : 0.3;
  auto& cam = rec.cameras.begin()->second;
  std::printf("start: f %.3f pp %.3f %.3f k1 %.5f k2 %.5f, %zu points\n", cam.f, cam.u0, cam.v0, cam.k1, cam.k2,
              rec.points.size());
  sfm::BundleAdjustmentOptions o;
  o.refine_principal_point = mode.find("fixpp") == std::string::npos;
  if (mode.find("fixf") != std::string::npos) o.refine_focal = false;
  o.max_iterations = 200;
  if (getenv("LS")) o.loss_scale_px = std::stod(getenv("LS"));
  if (getenv("HUBER")) o.loss = sfm::BundleAdjustmentOptions::Loss::kHuber;
  o.function_tolerance = 1e-10;
  o.initial_trust_region_radius = 1e8;
  o.compute_intrinsics_covariance = true;
  if (mode.find("nok") != std::string::npos) {
    o.refine_k1 = o.refine_k2 = false;
    cam.k1 = cam.k2 = 0;
  }
  if (mode.find("l2") != std::string::npos) o.loss = sfm::BundleAdjustmentOptions::Loss::kTrivial;
  if (mode.find("synth") != std::string::npos) {
    // Ideal observations: the model's points through its cameras with the true principal point, no distortion.
    core::Camera c = cam;
    c.u0 = tu;
    c.v0 = tv;
    c.k1 = c.k2 = 0;
    std::mt19937 rng(1);
    std::normal_distribution<double> g(0, noise);
    const bool corr = mode.find("corr") != std::string::npos;
    const bool shuf = mode.find("shuf") != std::string::npos, keep = mode.find("keepres") != std::string::npos;
    std::vector<Eigen::Vector2d> res;
    for (auto& [pid, p] : rec.points)
      for (auto& e : p.track) {
        auto& im = rec.images.at(e.image_id);
        res.push_back(im.points2d[e.point2d_idx] - cam.Project(im.pose.Transform(p.xyz)));
      }
    if (shuf) std::shuffle(res.begin(), res.end(), rng);
    size_t ri = 0;
    for (auto& [pid, p] : rec.points) {
      const double cu = g(rng), cv = g(rng);
      for (auto& e : p.track) {
        auto& im = rec.images.at(e.image_id);
        Eigen::Vector2d uv = c.Project(im.pose.Transform(p.xyz));
        if (corr)
          uv += Eigen::Vector2d(cu, cv) * 0.8 + Eigen::Vector2d{g(rng), g(rng)} * 0.6;
        else if (shuf || keep)
          uv += res[ri++];
        else
          uv += Eigen::Vector2d{g(rng), g(rng)};
        im.points2d[e.point2d_idx] = uv;
      }
    }
  }
  if (mode.find("trim") != std::string::npos) {
    const bool whole = mode.find("track") != std::string::npos;
    std::vector<double> errs;
    for (auto& [pid, p] : rec.points)
      for (auto& e : p.track) errs.push_back(sfm::ObservationError(rec, e.image_id, e.point2d_idx, p.xyz));
    std::vector<double> t = errs;
    std::nth_element(t.begin(), t.begin() + t.size() / 2, t.end());
    const double sigma = t[t.size() / 2] / 1.1774,
                 bound = sigma * (mode.find("trim2") != std::string::npos ? 2.0 : 3.44);
    size_t dropped_obs = 0, dropped_pts = 0;
    for (auto it = rec.points.begin(); it != rec.points.end();) {
      auto& p = it->second;
      std::vector<core::TrackElement> keep;
      bool bad = false;
      for (auto& e : p.track) {
        const double er = sfm::ObservationError(rec, e.image_id, e.point2d_idx, p.xyz);
        if (er > bound)
          bad = true;
        else
          keep.push_back(e);
      }
      if (whole && bad) keep.clear();
      if (keep.size() < 2) {
        for (auto& e : p.track) rec.images.at(e.image_id).point3d_ids[e.point2d_idx] = core::kNoPoint3D;
        dropped_obs += p.track.size();
        ++dropped_pts;
        it = rec.points.erase(it);
        continue;
      }
      for (auto& e : p.track) {
        bool k = false;
        for (auto& q : keep) k |= q.image_id == e.image_id && q.point2d_idx == e.point2d_idx;
        if (!k) {
          rec.images.at(e.image_id).point3d_ids[e.point2d_idx] = core::kNoPoint3D;
          ++dropped_obs;
        }
      }
      p.track = keep;
      ++it;
    }
    std::printf("trim: sigma %.3f bound %.3f, dropped %zu obs of %zu, %zu points\n", sigma, bound, dropped_obs,
                errs.size(), dropped_pts);
  }
  if (mode.find("centre") != std::string::npos) {
    cam.u0 = cam.width / 2.0;
    cam.v0 = cam.height / 2.0;
  }
  if (mode.find("truepp") != std::string::npos) {
    cam.u0 = tu;
    cam.v0 = tv;
  }
  if (mode.find("truef") != std::string::npos) cam.f = std::stod(argv[7]);
  sfm::BundleAdjustmentConfig cfg;
  auto s = sfm::BundleAdjust(&rec, cfg, o);
  Eigen::Matrix<double, core::kNumIntrinsics, core::kNumIntrinsics> C;
  C.setZero();
  if (!s.intrinsics_covariance.empty()) C = s.intrinsics_covariance.begin()->second;
  std::printf("%s: f %.3f pp %.3f %.3f (err %.3f %.3f) sig %.3f %.3f k1 %.5f k2 %.5f rms %.4f -> %.4f, %d it, n %d\n",
              mode.c_str(), cam.f, cam.u0, cam.v0, cam.u0 - tu, cam.v0 - tv, std::sqrt(C(core::kU0, core::kU0)),
              std::sqrt(C(core::kV0, core::kV0)), cam.k1, cam.k2, s.initial_rms_px, s.final_rms_px, s.num_iterations,
              s.num_residuals);
  if (argc > 6 && std::string(argv[6]).size()) io::WriteColmapText(rec, argv[6]);
}
