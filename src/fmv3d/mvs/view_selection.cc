#include "fmv3d/mvs/view_selection.h"

#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"

namespace fmv3d::mvs {
namespace {

constexpr double kDeg = M_PI / 180.0;

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(std::floor(q * (v.size() - 1) + 0.5)));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// Least-squares point closest to every optical axis: where an orbit or an object-centred capture looks.
// Returns false when the axes are (nearly) parallel, e.g. a nadir survey.
bool AxisConvergence(const std::map<uint32_t, ViewGeometry>& geoms, Eigen::Vector3d* point) {
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const auto& [id, g] : geoms) {
    const Eigen::Vector3d d = g.R.row(2).transpose().normalized();
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * g.Centre();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(A);
  if (es.eigenvalues()(0) < 1e-3 * es.eigenvalues()(2)) return false;
  *point = A.ldlt().solve(b);
  return point->allFinite();
}

}  // namespace

void ViewSelectionOptions::Check() const {
  if (max_neighbours < 1) throw Error("view selection: max_neighbours must be at least 1");
  if (min_shared_points < 1) throw Error("view selection: min_shared_points must be at least 1");
  if (!(min_angle_deg >= 0 && min_angle_deg < max_angle_deg && max_angle_deg <= 180))
    throw Error("view selection: need 0 <= min_angle_deg < max_angle_deg <= 180");
  if (!(good_angle_deg > 0)) throw Error("view selection: good_angle_deg must be positive");
  if (!(far_parallax_px >= 0)) throw Error("view selection: far_parallax_px must be >= 0");
  if (!(max_far_factor >= 1)) throw Error("view selection: max_far_factor must be at least 1");
  if (coverage_sources < 1) throw Error("view selection: coverage_sources must be at least 1");
  if (!(coverage_score_weight >= 0)) throw Error("view selection: coverage_score_weight must be >= 0");
}

std::vector<uint32_t> SelectReferenceViews(const core::Reconstruction& rec,
                                           const std::map<uint32_t, ViewGeometry>& geoms,
                                           const std::vector<uint32_t>& candidates,
                                           const ReferenceCoverOptions& options) {
  std::vector<uint32_t> all = candidates;
  std::sort(all.begin(), all.end());
  if (options.coverage <= 0 || all.size() <= 2) return all;
  std::map<uint32_t, size_t> index;
  for (size_t i = 0; i < all.size(); ++i) index[all[i]] = i;
  const double cos_cone = std::cos(options.cone_deg * kDeg);
  // Per point: chosen views still needed; per view: the points it sees.
  std::vector<int> need;
  std::vector<std::vector<uint32_t>> points_of(all.size());
  for (const auto& [pid, p] : rec.points) {
    Eigen::Vector3d mean_dir = Eigen::Vector3d::Zero();
    std::vector<double> dist;
    std::vector<bool> seen(all.size(), false);
    for (const auto& te : p.track) {
      auto it = index.find(te.image_id);
      if (it == index.end()) continue;
      const Eigen::Vector3d v = geoms.at(te.image_id).Centre() - p.xyz;
      mean_dir += v.normalized();
      dist.push_back(v.norm());
      seen[it->second] = true;
    }
    if (dist.empty() || mean_dir.norm() < 1e-9) continue;
    mean_dir.normalize();
    std::nth_element(dist.begin(), dist.begin() + static_cast<std::ptrdiff_t>(dist.size() / 2), dist.end());
    const double d_obs = dist[dist.size() / 2];
    for (size_t i = 0; i < all.size(); ++i) {
      if (seen[i]) continue;
      const ViewGeometry& g = geoms.at(all[i]);
      const Eigen::Vector3d v = g.Centre() - p.xyz;
      const double d = v.norm();
      if (d < 0.5 * d_obs || d > 2 * d_obs || v.dot(mean_dir) < cos_cone * d) continue;
      Eigen::Vector2d uv;
      if (g.Project(p.xyz, &uv) && uv.x() >= 0 && uv.y() >= 0 && uv.x() < g.width && uv.y() < g.height) seen[i] = true;
    }
    const auto k = static_cast<uint32_t>(need.size());
    int n_seen = 0;
    for (size_t i = 0; i < all.size(); ++i)
      if (seen[i]) points_of[i].push_back(k), ++n_seen;
    need.push_back(std::min(options.coverage, n_seen));
  }
  size_t demand = 0;
  for (int n : need) demand += static_cast<size_t>(n);
  if (demand == 0) return all;
  size_t met = 0;
  std::vector<bool> chosen(all.size(), false);
  while (static_cast<double>(met) < options.demand_fraction * static_cast<double>(demand)) {
    size_t best = all.size(), best_gain = 0;
    for (size_t i = 0; i < all.size(); ++i) {
      if (chosen[i]) continue;
      size_t gain = 0;
      for (uint32_t k : points_of[i]) gain += need[k] > 0 ? 1 : 0;
      if (gain > best_gain) best_gain = gain, best = i;
    }
    if (best == all.size()) break;  // nothing left to gain
    chosen[best] = true;
    for (uint32_t k : points_of[best])
      if (need[k] > 0) --need[k], ++met;
  }
  std::vector<uint32_t> out;
  for (size_t i = 0; i < all.size(); ++i)
    if (chosen[i]) out.push_back(all[i]);
  return out;
}

namespace {

// The points a reference view's neighbours are scored on: the sparse points it sees (with their tracks), or
// stand-ins on a grid at the depth where the views' axes converge.
struct ViewSelectionPoints {
  std::vector<Eigen::Vector3d> xyz;
  std::vector<const core::Point3D*> sparse;  // parallel to xyz when they are sparse points
  std::vector<double> depths;                // camera-frame z of the sparse points
};

// Fills *pts and the depth range of *sel from the points `observed` by the reference (when there are enough of
// them), else from the axes' convergence point (nullptr: none). False, with sel->problem set, when neither
// gives a depth.
bool GatherViewSelectionPoints(const ViewGeometry& ref, const std::vector<const core::Point3D*>* observed,
                               const Eigen::Vector3d* convergence, const ViewSelectionOptions& options,
                               ReferenceSelection* sel, ViewSelectionPoints* pts) {
  if (observed && observed->size() >= static_cast<size_t>(options.min_shared_points)) {
    for (const auto* p : *observed) {
      Eigen::Vector2d uv;
      if (ref.Project(p->xyz, &uv)) {
        pts->xyz.push_back(p->xyz);
        pts->sparse.push_back(p);
      }
    }
    sel->from_sparse_points = true;
  }
  if (sel->from_sparse_points) {
    for (const auto& X : pts->xyz) pts->depths.push_back((ref.R * X + ref.t).z());
    const double lo = Percentile(pts->depths, 0.01), hi = Percentile(pts->depths, 0.99);
    sel->depth_min = 0.6 * lo;
    sel->depth_max = 1.6 * hi;
    return true;
  }
  double z0 = 0;
  if (convergence) z0 = (ref.R * *convergence + ref.t).z();
  if (!(z0 > 0)) {
    sel->problem = "no sparse points and no common viewing target to estimate a depth range";
    return false;
  }
  sel->depth_min = z0 / 3;
  sel->depth_max = z0 * 3;
  for (int gy = 0; gy < 9; ++gy)
    for (int gx = 0; gx < 16; ++gx)
      pts->xyz.push_back(ref.Unproject({(gx + 0.5) * ref.width / 16.0, (gy + 0.5) * ref.height / 9.0}, z0));
  return true;
}

// Whether source view `src` shares reference point k: with sparse points, when src observes it (its track) or
// sees it — the point projects into src from the same side of the surface (within max_angle of the reference's
// ray) at a comparable distance. Video tracks break into short pieces, so tracks alone would only pair
// neighbouring keyframes; the wider baselines over the whole clip are what far surfaces need. With stand-ins,
// when the point projects into src.
bool SharesViewSelectionPoint(const ViewGeometry& ref, uint32_t src_id, const ViewGeometry& src,
                              const ViewSelectionPoints& pts, size_t k, const ViewSelectionOptions& options) {
  const Eigen::Vector3d& X = pts.xyz[k];
  if (!pts.sparse.empty()) {
    const auto& tr = pts.sparse[k]->track;
    if (std::any_of(tr.begin(), tr.end(), [&](const core::TrackElement& te) { return te.image_id == src_id; }))
      return true;
    if (!options.sources_by_projection) return false;
    const Eigen::Vector3d a = ref.Centre() - X, b = src.Centre() - X;
    const double ratio = b.norm() / a.norm();
    if (ratio < 0.5 || ratio > 2 || a.dot(b) < std::cos(options.max_angle_deg * kDeg) * a.norm() * b.norm())
      return false;
  }
  Eigen::Vector2d uv;
  return src.Project(X, &uv) && !(uv.x() < 0 || uv.y() < 0 || uv.x() > src.width || uv.y() > src.height);
}

// Source view src (nb->image_id) scored against the reference's points: each shared point within the angle
// bounds adds its angle weight times its scale weight. False when src does not qualify as a neighbour.
bool ScoreViewSelectionSource(const ViewGeometry& ref, const ViewGeometry& src, const ViewSelectionPoints& pts,
                              const ViewSelectionOptions& options, Neighbour* nb,
                              std::vector<std::pair<uint32_t, float>>* weights) {
  const Eigen::Vector3d cr = ref.Centre(), cj = src.Centre();
  const double fr = ref.K(1, 1), fj = src.K(1, 1);
  std::vector<double> angles;
  for (size_t k = 0; k < pts.xyz.size(); ++k) {
    if (!SharesViewSelectionPoint(ref, nb->image_id, src, pts, k, options)) continue;
    const Eigen::Vector3d& X = pts.xyz[k];
    const Eigen::Vector3d a = cr - X, b = cj - X;
    const double alpha = std::atan2(a.cross(b).norm(), a.dot(b));
    angles.push_back(alpha);
    if (alpha < options.min_angle_deg * kDeg || alpha > options.max_angle_deg * kDeg) continue;
    const double w_angle = std::min(1.0, std::pow(alpha / (options.good_angle_deg * kDeg), 2));
    const double s = (a.norm() / fr) / (b.norm() / fj);
    const double w_scale = s < 1 ? s : (s > 2 ? 2 / s : 1.0);
    nb->score += w_angle * w_scale;
    weights->emplace_back(static_cast<uint32_t>(k), static_cast<float>(w_angle * w_scale));
  }
  nb->shared_points = static_cast<int>(angles.size());
  if (nb->shared_points < options.min_shared_points || nb->score <= 0) return false;
  nb->median_angle_deg = Percentile(angles, 0.5) / kDeg;
  return nb->median_angle_deg >= options.min_angle_deg && nb->median_angle_deg <= options.max_angle_deg;
}

// The best max_neighbours candidates, ordered greedily: each next one maximises the part of the reference it
// covers, each point weighted by its share of its image cell (the area counts, not the feature density) and by
// 1/(c + 1) while c < coverage_sources chosen views cover it already (a first source where there is none counts
// most), plus coverage_score_weight × its score relative to the best. By score alone, a grid survey's best
// sources can all overlap one side of the reference, and PatchMatch, which averages the best few sources'
// costs per pixel, then matches the rest of the image against nothing. `weights[j]`: candidate j's positive
// weight on each point it shares.
std::vector<Neighbour> OrderForCoverage(const ViewGeometry& ref, const ViewSelectionPoints& pts,
                                        std::vector<Neighbour> cands,
                                        const std::vector<std::vector<std::pair<uint32_t, float>>>& weights,
                                        const ViewSelectionOptions& options) {
  const size_t n = cands.size();
  const size_t keep = std::min(n, static_cast<size_t>(options.max_neighbours));
  if (n < 2) return cands;
  constexpr int kCells = 8;  // per image side
  std::vector<int> cell(pts.xyz.size(), -1);
  std::vector<int> per_cell(static_cast<size_t>(kCells) * kCells, 0);
  for (size_t k = 0; k < pts.xyz.size(); ++k) {
    Eigen::Vector2d uv;
    if (!ref.Project(pts.xyz[k], &uv)) continue;
    const int cx = std::clamp(static_cast<int>(uv.x() * kCells / ref.width), 0, kCells - 1);
    const int cy = std::clamp(static_cast<int>(uv.y() * kCells / ref.height), 0, kCells - 1);
    cell[k] = cy * kCells + cx;
    ++per_cell[cell[k]];
  }
  std::vector<double> area(pts.xyz.size(), 0);
  double total_area = 0;
  for (size_t k = 0; k < pts.xyz.size(); ++k)
    if (cell[k] >= 0) total_area += area[k] = 1.0 / per_cell[cell[k]];
  double best_score = 0;
  for (const auto& c : cands) best_score = std::max(best_score, c.score);
  if (!(total_area > 0) || !(best_score > 0)) {  // nothing to cover: by score
    std::sort(cands.begin(), cands.end(), [](const Neighbour& a, const Neighbour& b) {
      return a.score != b.score ? a.score > b.score : a.image_id < b.image_id;
    });
    cands.resize(keep);
    return cands;
  }
  std::vector<int> cover(pts.xyz.size(), 0);
  std::vector<bool> taken(n, false);
  std::vector<Neighbour> out;
  out.reserve(n);
  while (out.size() < keep) {
    size_t best = n;
    double best_gain = -1;
    for (size_t j = 0; j < n; ++j) {
      if (taken[j]) continue;
      double gained = 0;
      for (const auto& [k, w] : weights[j])
        if (cover[k] < options.coverage_sources) gained += area[k] * w / (cover[k] + 1);
      const double gain = gained / total_area + options.coverage_score_weight * cands[j].score / best_score;
      if (gain > best_gain || (gain == best_gain && cands[j].image_id < cands[best].image_id))
        best_gain = gain, best = j;
    }
    taken[best] = true;
    for (const auto& [k, w] : weights[best]) ++cover[k];
    out.push_back(cands[best]);
  }
  return out;
}

// The neighbours and depth range of one reference view.
ReferenceSelection SelectForReference(const ViewGeometry& ref, const std::map<uint32_t, ViewGeometry>& geoms,
                                      const std::vector<const core::Point3D*>* observed,
                                      const Eigen::Vector3d* convergence, const ViewSelectionOptions& options) {
  ReferenceSelection sel;
  ViewSelectionPoints pts;
  if (!GatherViewSelectionPoints(ref, observed, convergence, options, &sel, &pts)) return sel;
  std::vector<Neighbour> cands;
  std::vector<std::vector<std::pair<uint32_t, float>>> weights;
  for (const auto& [jd, src] : geoms) {
    if (jd == ref.image_id) continue;
    Neighbour nb;
    nb.image_id = jd;
    std::vector<std::pair<uint32_t, float>> w;
    if (ScoreViewSelectionSource(ref, src, pts, options, &nb, &w)) {
      cands.push_back(nb);
      weights.push_back(std::move(w));
    }
  }
  cands = OrderForCoverage(ref, pts, std::move(cands), weights, options);
  // Far surfaces: the sparse points rarely reach them (their short tracks triangulate too flatly), so the
  // range extends to where the widest chosen baseline still gives far_parallax_px of parallax — farther,
  // nothing can be resolved; nearer, a cut-off range would hide surface the clip's baseline can resolve.
  if (sel.from_sparse_points && options.far_parallax_px > 0 && !cands.empty()) {
    double baseline = 0;
    for (const auto& nb : cands) baseline = std::max(baseline, (geoms.at(nb.image_id).Centre() - ref.Centre()).norm());
    const double z_far = ref.K(1, 1) * baseline / options.far_parallax_px;
    const double hi = Percentile(pts.depths, 0.99);
    sel.depth_max = std::max(sel.depth_max, std::min(z_far, options.max_far_factor * hi));
  }
  sel.neighbours = std::move(cands);
  if (sel.neighbours.empty())
    sel.problem = "no other view shares enough of its surface at a triangulation angle in [" +
                  std::to_string(options.min_angle_deg) + ", " + std::to_string(options.max_angle_deg) + "] deg";
  return sel;
}

}  // namespace

std::map<uint32_t, ReferenceSelection> SelectViews(const core::Reconstruction& rec,
                                                   const std::map<uint32_t, ViewGeometry>& geoms,
                                                   const ViewSelectionOptions& options) {
  options.Check();
  std::vector<uint32_t> ids;
  ids.reserve(geoms.size());
  for (const auto& [id, g] : geoms) ids.push_back(id);
  // Sparse points observed by each image.
  std::map<uint32_t, std::vector<const core::Point3D*>> observed;
  for (const auto& [pid, p] : rec.points) {
    for (const auto& te : p.track)
      if (geoms.count(te.image_id)) observed[te.image_id].push_back(&p);
  }
  Eigen::Vector3d convergence;
  const bool has_convergence = AxisConvergence(geoms, &convergence);

  std::vector<ReferenceSelection> out(ids.size());
  tbb::parallel_for(size_t{0}, ids.size(), [&](size_t ri) {
    const ViewGeometry& ref = geoms.at(ids[ri]);
    const auto obs = observed.find(ref.image_id);
    out[ri] = SelectForReference(ref, geoms, obs == observed.end() ? nullptr : &obs->second,
                                 has_convergence ? &convergence : nullptr, options);
  });
  std::map<uint32_t, ReferenceSelection> result;
  for (size_t i = 0; i < ids.size(); ++i) result[ids[i]] = std::move(out[i]);
  return result;
}

}  // namespace fmv3d::mvs
