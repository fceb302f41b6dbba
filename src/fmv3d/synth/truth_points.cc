#include "fmv3d/synth/truth_points.h"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <random>
#include <set>

#include "fmv3d/core/error.h"

namespace fmv3d::synth {

void TruthPointOptions::Check() const {
  if (points < 1) throw Error("truth points: --points must be ≥ 1");
  if (min_frames < 1) throw Error("truth points: --min-frames must be ≥ 1");
  if (noise_px < 0) throw Error("truth points: --noise must be ≥ 0");
}

std::vector<TruthPoint> SelectTruthPoints(const core::Reconstruction& truth, const TruthPointOptions& o) {
  o.Check();
  const std::set<std::string> allowed(o.allowed_frames.begin(), o.allowed_frames.end());
  for (const auto& name : o.required_frames)
    if (!truth.FindImageByName(name)) throw Error(fmt::format("truth points: frame \"{}\" is not in the truth", name));
  // Eligible points with their (exact) observations.
  std::vector<TruthPoint> eligible;
  for (const auto& [id, p] : truth.points) {
    TruthPoint tp;
    tp.xyz = p.xyz;
    std::set<std::string> seen;
    bool near_border = false;
    for (const auto& el : p.track) {
      const auto it = truth.images.find(el.image_id);
      if (it == truth.images.end()) continue;
      const core::Image& im = it->second;
      if (!allowed.empty() && !allowed.count(im.name)) continue;
      if (seen.count(im.name)) continue;
      const core::Camera& cam = truth.cameras.at(im.camera_id);
      const Eigen::Vector3d xc = im.pose.Transform(p.xyz);
      if (xc.z() <= 0) continue;
      const Eigen::Vector2d uv = cam.Project(xc);
      if (!cam.InImage(uv, 1)) continue;
      const bool required =
          std::find(o.required_frames.begin(), o.required_frames.end(), im.name) != o.required_frames.end();
      if (required && !cam.InImage(uv, o.border_px)) near_border = true;
      seen.insert(im.name);
      tp.observations.push_back({im.name, uv.x(), uv.y()});
    }
    if (near_border || static_cast<int>(tp.observations.size()) < o.min_frames) continue;
    if (!std::all_of(o.required_frames.begin(), o.required_frames.end(),
                     [&](const std::string& n) { return seen.count(n) > 0; }))
      continue;
    eligible.push_back(std::move(tp));
  }
  if (static_cast<int>(eligible.size()) < o.points)
    throw Error(fmt::format("truth points: only {} scene points are seen by ≥ {} frames{}; {} wanted", eligible.size(),
                            o.min_frames, o.required_frames.empty() ? "" : " including the required ones", o.points));
  // Farthest-point sampling from the most-seen point.
  size_t first = 0;
  for (size_t i = 1; i < eligible.size(); ++i)
    if (eligible[i].observations.size() > eligible[first].observations.size()) first = i;
  std::vector<size_t> chosen = {first};
  std::vector<double> dist(eligible.size(), std::numeric_limits<double>::infinity());
  while (static_cast<int>(chosen.size()) < o.points) {
    const Eigen::Vector3d& last = eligible[chosen.back()].xyz;
    size_t best = 0;
    double best_d = -1;
    for (size_t i = 0; i < eligible.size(); ++i) {
      dist[i] = std::min(dist[i], (eligible[i].xyz - last).norm());
      if (dist[i] > best_d) {
        best_d = dist[i];
        best = i;
      }
    }
    chosen.push_back(best);
  }
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> noise(0.0, o.noise_px);
  std::vector<TruthPoint> out;
  for (size_t i : chosen) {
    TruthPoint tp = eligible[i];
    if (o.noise_px > 0)
      for (auto& ob : tp.observations) {
        const core::Camera& cam = truth.cameras.at(truth.FindImageByName(ob.frame)->camera_id);
        ob.x = std::clamp(ob.x + noise(rng), 0.0, double(cam.width));  // a click stays inside the image
        ob.y = std::clamp(ob.y + noise(rng), 0.0, double(cam.height));
      }
    out.push_back(std::move(tp));
  }
  return out;
}

}  // namespace fmv3d::synth
