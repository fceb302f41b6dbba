#include "fmv3d/sfm/guided_completion.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <tuple>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace fmv3d::sfm {
namespace {

// Decoy shifts (fractions of the image width, height): the quarter-image grid, farthest from the projection first.
constexpr int kMaxDecoys = 8;
constexpr double kDecoyShifts[kMaxDecoys][2] = {{0.5, 0.5},  {0.5, 0},    {0, 0.5},    {0.25, 0.5},
                                                {0.75, 0.5}, {0.5, 0.25}, {0.5, 0.75}, {0.25, 0.25}};

}  // namespace

void GuidedCompletionOptions::Check() const {
  if (!(max_error_px > 0)) throw Error("guided completion: max_error_px must be > 0");
  if (!(false_accept_rate > 0 && false_accept_rate < 1))
    throw Error("guided completion: false_accept_rate must be in (0, 1)");
  if (min_decoys_for_bound < 1) throw Error("guided completion: min_decoys_for_bound must be ≥ 1");
  if (!(search_mass > 0 && search_mass < 1)) throw Error("guided completion: search_mass must be in (0, 1)");
  if (min_bin_observations < 1) throw Error("guided completion: min_bin_observations must be ≥ 1");
  if (!(ratio > 0 && ratio <= 1)) throw Error("guided completion: ratio must be in (0, 1]");
  if (decoys_per_projection < 1 || decoys_per_projection > kMaxDecoys)
    throw Error("guided completion: decoys_per_projection must be in [1, " + std::to_string(kMaxDecoys) + "]");
}

namespace {

double MedianSigma(std::vector<double> errors) {
  if (errors.empty()) return 0;
  auto mid = errors.begin() + errors.size() / 2;
  std::nth_element(errors.begin(), mid, errors.end());
  return *mid / std::sqrt(2 * std::log(2.0));
}

// d(projection)/d(world point) of image im.
Eigen::Matrix<double, 2, 3> WorldJacobian(const core::Reconstruction& rec, const core::Image& im,
                                          const Eigen::Vector3d& xc) {
  return rec.cameras.at(im.camera_id).ProjectJacobian(xc) * im.pose.R();
}

// The point's covariance from its observations (Gauss–Newton, cameras held); false when they do not determine it.
bool PointCovariance(const core::Reconstruction& rec, const core::Point3D& p, const KeypointNoise& noise,
                     Eigen::Matrix3d* cov) {
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
  for (const auto& t : p.track) {
    const core::Image& im = rec.images.at(t.image_id);
    const Eigen::Vector3d xc = im.pose.Transform(p.xyz);
    if (!(xc.z() > 0)) continue;
    const Eigen::Matrix<double, 2, 3> J = WorldJacobian(rec, im, xc);
    const double s = noise.Sigma(t.image_id, t.point2d_idx);
    info += J.transpose() * J / (s * s);
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(info);
  const Eigen::Vector3d& ev = eig.eigenvalues();
  if (!(ev.minCoeff() > 1e-12 * ev.maxCoeff()) || !std::isfinite(ev.maxCoeff())) return false;
  *cov = eig.eigenvectors() * ev.cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
  return true;
}

// The point's covariance projected into image im (pixels²).
Eigen::Matrix2d ProjectedCovariance(const core::Reconstruction& rec, const Eigen::Matrix3d& point_cov,
                                    const core::Image& im, const Eigen::Vector3d& xc) {
  const Eigen::Matrix<double, 2, 3> J = WorldJacobian(rec, im, xc);
  return J * point_cov * J.transpose();
}

}  // namespace

int KeypointNoise::Bin(float scale) {
  if (!(scale > 1)) return 0;
  return std::min(kBins - 1, static_cast<int>(std::floor(2 * std::log2(scale))));
}

KeypointNoise::KeypointNoise(const core::Reconstruction& rec, const KeypointScales& scales, int min_observations) {
  by_bin_.fill(0);
  for (const auto& [id, im] : rec.images) {
    auto sc = scales.find(id);
    if (sc != scales.end() && sc->second && sc->second->size() == im.points2d.size()) scales_[id] = sc->second;
  }
  std::array<std::vector<double>, kBins> per_bin;
  std::vector<double> all;
  std::set<uint32_t> images;
  size_t points = 0;  // with an observation in front of its camera: the ones the adjustment fitted
  for (const auto& [pid, p] : rec.points) {
    const size_t before = all.size();
    for (const auto& t : p.track) {
      const double e = ObservationError(rec, t.image_id, t.point2d_idx, p.xyz);
      if (!std::isfinite(e)) continue;
      all.push_back(e);
      images.insert(t.image_id);
      auto sc = scales_.find(t.image_id);
      if (sc != scales_.end()) per_bin[Bin((*sc->second)[t.point2d_idx])].push_back(e);
    }
    points += all.size() > before;
  }
  const double measurements = 2.0 * all.size();
  const double fitted = 3.0 * points + 6.0 * images.size();
  if (!(measurements > fitted)) return;
  const double dof = std::sqrt(measurements / (measurements - fitted));
  overall_ = dof * MedianSigma(std::move(all));
  for (int b = 0; b < kBins; ++b) {
    const int n = static_cast<int>(per_bin[b].size());
    const double s = dof * MedianSigma(std::move(per_bin[b]));
    by_bin_[b] = n >= min_observations && s > 0 ? s : overall_;
  }
}

double KeypointNoise::Sigma(uint32_t image_id, uint32_t kp) const {
  auto sc = scales_.find(image_id);
  return sc == scales_.end() ? overall_ : by_bin_[Bin((*sc->second)[kp])];
}

Eigen::Matrix2d ProjectedPointCovariance(const core::Reconstruction& rec, const core::Point3D& point, uint32_t image_id,
                                         const KeypointNoise& noise) {
  Eigen::Matrix3d cov;
  const core::Image& im = rec.images.at(image_id);
  const Eigen::Vector3d xc = im.pose.Transform(point.xyz);
  if (!(xc.z() > 0) || !PointCovariance(rec, point, noise, &cov))
    return Eigen::Matrix2d::Constant(std::numeric_limits<double>::infinity());
  return ProjectedCovariance(rec, cov, im, xc);
}

namespace {

int SquaredDistance(const features::Descriptors& a, uint32_t i, const features::Descriptors& b, uint32_t j) {
  const uint8_t* x = a.row(i).data();
  const uint8_t* y = b.row(j).data();
  int s = 0;
  for (int k = 0; k < 128; ++k) {
    const int d = int(x[k]) - int(y[k]);
    s += d * d;
  }
  return s;
}

// The free keypoints (observing no point) of one image in square cells of the search radius: a query looks
// at the 3 x 3 cells around its cell.
class FreeKeypointGrid {
 public:
  FreeKeypointGrid(const core::Image& im, const core::Camera& cam, double cell) : cell_(cell) {
    cols_ = std::max(1, static_cast<int>(std::ceil(cam.width / cell)) + 1);
    rows_ = std::max(1, static_cast<int>(std::ceil(cam.height / cell)) + 1);
    start_.assign(static_cast<size_t>(cols_) * rows_ + 1, 0);
    std::vector<int> cell_of(im.points2d.size(), -1);
    for (size_t k = 0; k < im.points2d.size(); ++k) {
      if (im.point3d_ids[k] != core::kNoPoint3D) continue;
      cell_of[k] = Cell(im.points2d[k]);
      if (cell_of[k] >= 0) ++start_[cell_of[k] + 1];
    }
    for (size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
    index_.resize(start_.back());
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    for (size_t k = 0; k < cell_of.size(); ++k)
      if (cell_of[k] >= 0) index_[fill[cell_of[k]]++] = static_cast<uint32_t>(k);
  }
  template <typename Visit>
  void Near(const Eigen::Vector2d& uv, Visit visit) const {
    const int cx = static_cast<int>(std::floor(uv.x() / cell_)), cy = static_cast<int>(std::floor(uv.y() / cell_));
    for (int y = std::max(0, cy - 1); y <= std::min(rows_ - 1, cy + 1); ++y)
      for (int x = std::max(0, cx - 1); x <= std::min(cols_ - 1, cx + 1); ++x) {
        const int c = y * cols_ + x;
        for (int k = start_[c]; k < start_[c + 1]; ++k) visit(index_[k]);
      }
  }

 private:
  int Cell(const Eigen::Vector2d& p) const {
    const int x = static_cast<int>(std::floor(p.x() / cell_)), y = static_cast<int>(std::floor(p.y() / cell_));
    if (x < 0 || y < 0 || x >= cols_ || y >= rows_) return -1;
    return y * cols_ + x;
  }
  double cell_;
  int cols_ = 1, rows_ = 1;
  std::vector<int> start_;
  std::vector<uint32_t> index_;
};

// Squared normalised radius of the image's farthest corner, widened a little: projections beyond it are where
// a polynomial distortion model folds back into the image, not where the lens looks.
double MaxNormalisedRadius2(const core::Camera& cam) {
  double r2 = 0;
  for (double u : {0.0, double(cam.width)})
    for (double v : {0.0, double(cam.height)}) r2 = std::max(r2, cam.Unproject({u, v}).head<2>().squaredNorm());
  return 1.44 * r2;
}

// The members' nearest-member distances: for every observation of a point with ≥ 2 described observations,
// the smallest squared distance to another observation of the same point.
std::vector<int> MemberDistances(const core::Reconstruction& rec,
                                 const std::map<uint32_t, const features::Descriptors*>& descriptors) {
  std::vector<int> out;
  for (const auto& [pid, p] : rec.points) {
    std::vector<std::pair<const features::Descriptors*, uint32_t>> rows;
    for (const auto& t : p.track) {
      auto d = descriptors.find(t.image_id);
      if (d != descriptors.end()) rows.emplace_back(d->second, t.point2d_idx);
    }
    if (rows.size() < 2) continue;
    for (size_t a = 0; a < rows.size(); ++a) {
      int best = std::numeric_limits<int>::max();
      for (size_t b = 0; b < rows.size(); ++b)
        if (a != b)
          best = std::min(best, SquaredDistance(*rows[a].first, rows[a].second, *rows[b].first, rows[b].second));
      out.push_back(best);
    }
  }
  return out;
}

constexpr int kNone = std::numeric_limits<int>::max();

struct Search {
  int best = kNone;    // smallest descriptor distance to the track inside the search ellipse
  uint32_t kp = 0;     // its keypoint
  int second = kNone;  // the next smallest inside the radius cap
};

// The search region of keypoint k of the image: rᵀ S⁻¹ r ≤ χ², S = σ_k² I + P (P: the point's covariance
// projected into the image).
bool InSearchRegion(const Eigen::Vector2d& r, const Eigen::Matrix2d& P, double sigma, double chi2) {
  const Eigen::Matrix2d S = P + sigma * sigma * Eigen::Matrix2d::Identity();
  return r.dot(S.inverse() * r) <= chi2;
}

// The free keypoints around `at`: the one inside its search region that looks most like the track (smallest
// squared distance to any member's descriptor), and its most similar rival inside the radius cap.
Search FindKeypoint(const FreeKeypointGrid& grid, const core::Image& im, const features::Descriptors& dj,
                    const std::vector<std::pair<const features::Descriptors*, uint32_t>>& members,
                    const Eigen::Vector2d& at, const Eigen::Matrix2d& P, const KeypointNoise& noise, double chi2,
                    double cap2) {
  Search out;
  grid.Near(at, [&](uint32_t k) {
    const Eigen::Vector2d r = im.points2d[k] - at;
    if (r.squaredNorm() > cap2) return;
    int d = kNone;
    for (const auto& [desc, row] : members) d = std::min(d, SquaredDistance(*desc, row, dj, k));
    if (d < out.best && InSearchRegion(r, P, noise.Sigma(im.id, k), chi2)) {
      out.second = std::min(out.second, out.best);
      out.best = d, out.kp = k;
    } else {
      out.second = std::min(out.second, d);
    }
  });
  return out;
}

struct Claim {
  int distance;
  uint32_t image_id, kp;
  uint64_t point_id;
};

}  // namespace

GuidedCompletionStats CompleteTracksByProjection(core::Reconstruction* rec,
                                                 const std::map<uint32_t, const features::Descriptors*>& descriptors,
                                                 const std::map<uint32_t, std::set<uint32_t>>& covisible,
                                                 const GuidedCompletionOptions& options, const KeypointScales& scales) {
  options.Check();
  GuidedCompletionStats stats;
  for (const auto& [id, d] : descriptors) {
    auto im = rec->images.find(id);
    if (im != rec->images.end() && static_cast<size_t>(d->rows()) != im->second.points2d.size())
      throw Error("guided completion: image " + std::to_string(id) + " has " + std::to_string(d->rows()) +
                  " descriptors for " + std::to_string(im->second.points2d.size()) + " keypoints");
  }
  std::vector<int> members = MemberDistances(*rec, descriptors);
  stats.member_distances = members.size();
  if (!members.empty()) {
    std::nth_element(members.begin(), members.begin() + members.size() / 2, members.end());
    stats.member_median = members[members.size() / 2];
  }

  stats.added.clear();
  const KeypointNoise noise(*rec, scales, options.min_bin_observations);
  if (!(noise.overall() > 0)) return stats;  // no noise measurable: no search region
  stats.sigma_px = noise.overall();
  std::map<uint32_t, FreeKeypointGrid> grids;
  std::map<uint32_t, double> max_r2;
  for (const auto& [id, im] : rec->images) {
    if (!descriptors.count(id)) continue;
    const core::Camera& cam = rec->cameras.at(im.camera_id);
    grids.emplace(id, FreeKeypointGrid(im, cam, options.max_error_px));
    if (!max_r2.count(im.camera_id)) max_r2[im.camera_id] = MaxNormalisedRadius2(cam);
  }
  const double cap2 = options.max_error_px * options.max_error_px;
  const double chi2 = -2 * std::log(1 - options.search_mass);  // χ²(2) quantile
  std::vector<Claim> claims;
  std::vector<int> decoys;
  std::vector<double> radii;
  for (const auto& [pid, p] : rec->points) {
    std::set<uint32_t> in_track, targets;
    for (const auto& t : p.track) in_track.insert(t.image_id);
    for (uint32_t id : in_track) {
      auto c = covisible.find(id);
      if (c != covisible.end()) targets.insert(c->second.begin(), c->second.end());
    }
    ++stats.points;
    Eigen::Matrix3d point_cov;
    if (!PointCovariance(*rec, p, noise, &point_cov)) continue;
    std::vector<std::pair<const features::Descriptors*, uint32_t>> members_of;
    for (const auto& t : p.track) {
      auto d = descriptors.find(t.image_id);
      if (d != descriptors.end()) members_of.emplace_back(d->second, t.point2d_idx);
    }
    for (uint32_t id : targets) {
      if (in_track.count(id) || !grids.count(id)) continue;
      const core::Image& im = rec->images.at(id);
      const core::Camera& cam = rec->cameras.at(im.camera_id);
      const Eigen::Vector3d xc = im.pose.Transform(p.xyz);
      if (!(xc.z() > 0)) continue;
      if ((xc.head<2>() / xc.z()).squaredNorm() > max_r2.at(im.camera_id)) continue;
      const Eigen::Vector2d uv = cam.Project(xc);
      if (!cam.InImage(uv)) continue;
      ++stats.projections;
      const Eigen::Matrix2d P = ProjectedCovariance(*rec, point_cov, im, xc);
      const double s0 = noise.overall();
      radii.push_back(
          std::min(options.max_error_px,
                   std::sqrt(chi2 * (P + s0 * s0 * Eigen::Matrix2d::Identity()).eigenvalues().real().maxCoeff())));
      const features::Descriptors& dj = *descriptors.at(id);
      const Search found = FindKeypoint(grids.at(id), im, dj, members_of, uv, P, noise, chi2, cap2);
      if (found.best != kNone) {
        ++stats.candidates;
        // Lowe's ratio test against the rival: a second keypoint near the projection that looks about as much
        // like the track (repeated texture, a duplicate detection) leaves the choice to chance.
        if (options.ratio < 1 && found.second != kNone && !(found.best < options.ratio * options.ratio * found.second))
          ++stats.ambiguous;
        else
          claims.push_back({found.best, id, found.kp, pid});
      }
      // The decoys: the same search a quarter to half an image away, where no keypoint is this point except by
      // chance. Several per projection: a search region of a pixel or two holds a keypoint rarely.
      for (int i = 0; i < options.decoys_per_projection; ++i) {
        const Eigen::Vector2d at(std::fmod(uv.x() + kDecoyShifts[i][0] * cam.width, double(cam.width)),
                                 std::fmod(uv.y() + kDecoyShifts[i][1] * cam.height, double(cam.height)));
        const int decoy = FindKeypoint(grids.at(id), im, dj, members_of, at, P, noise, chi2, cap2).best;
        if (decoy != kNone) decoys.push_back(decoy);
      }
    }
  }
  if (!radii.empty()) {
    std::nth_element(radii.begin(), radii.begin() + radii.size() / 2, radii.end());
    stats.median_radius_px = radii[radii.size() / 2];
  }
  stats.decoys = decoys.size();
  if (static_cast<int>(decoys.size()) < options.min_decoys_for_bound) return stats;
  std::sort(decoys.begin(), decoys.end());
  // Accepting d ≤ bound takes at most this share of the decoys (a keypoint there by chance).
  const int bound = decoys[static_cast<size_t>(options.false_accept_rate * (decoys.size() - 1))] - 1;
  stats.descriptor_bound = bound;
  claims.erase(std::remove_if(claims.begin(), claims.end(), [&](const Claim& c) { return c.distance > bound; }),
               claims.end());
  // Most similar first: a keypoint goes to the point it resembles most.
  std::sort(claims.begin(), claims.end(), [](const Claim& a, const Claim& b) {
    return std::tie(a.distance, a.image_id, a.kp, a.point_id) < std::tie(b.distance, b.image_id, b.kp, b.point_id);
  });
  for (const Claim& c : claims) {
    core::Image& im = rec->images.at(c.image_id);
    if (im.point3d_ids[c.kp] != core::kNoPoint3D) {
      ++stats.conflicts;
      continue;
    }
    im.point3d_ids[c.kp] = static_cast<int64_t>(c.point_id);
    rec->points.at(c.point_id).track.push_back({c.image_id, c.kp});
    stats.added.push_back({c.point_id, {c.image_id, c.kp}});
    ++stats.accepted;
  }
  return stats;
}

size_t RemoveAdditionsThatDoNotFit(core::Reconstruction* rec,
                                   const std::vector<std::pair<uint64_t, core::TrackElement>>& added,
                                   const GuidedCompletionOptions& options, const KeypointScales& scales) {
  options.Check();
  const KeypointNoise noise(*rec, scales, options.min_bin_observations);
  if (!(noise.overall() > 0)) return 0;
  const double k = std::sqrt(-2 * std::log(1 - options.search_mass));
  size_t removed = 0;
  for (const auto& addition : added) {
    const core::TrackElement& el = addition.second;  // not a structured binding: the lambda below captures it
    auto p = rec->points.find(addition.first);
    if (p == rec->points.end()) continue;
    auto& track = p->second.track;
    auto it = std::find_if(track.begin(), track.end(), [&](const core::TrackElement& t) {
      return t.image_id == el.image_id && t.point2d_idx == el.point2d_idx;
    });
    if (it == track.end() || track.size() <= 2) continue;
    const double bound = std::min(options.max_error_px, k * noise.Sigma(el.image_id, el.point2d_idx));
    if (ObservationError(*rec, el.image_id, el.point2d_idx, p->second.xyz) <= bound) continue;
    rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
    track.erase(it);
    ++removed;
  }
  return removed;
}

}  // namespace fmv3d::sfm
