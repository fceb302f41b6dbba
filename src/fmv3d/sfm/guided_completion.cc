#include "fmv3d/sfm/guided_completion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>
#include <vector>

#include "fmv3d/core/error.h"

namespace fmv3d::sfm {

void GuidedCompletionOptions::Check() const {
  if (!(max_error_px > 0)) throw Error("guided completion: max_error_px must be > 0");
  if (!(false_accept_rate > 0 && false_accept_rate < 1))
    throw Error("guided completion: false_accept_rate must be in (0, 1)");
  if (min_decoys_for_bound < 1) throw Error("guided completion: min_decoys_for_bound must be ≥ 1");
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

struct Claim {
  int distance;
  uint32_t image_id, kp;
  uint64_t point_id;
};

}  // namespace

GuidedCompletionStats CompleteTracksByProjection(core::Reconstruction* rec,
                                                 const std::map<uint32_t, const features::Descriptors*>& descriptors,
                                                 const std::map<uint32_t, std::set<uint32_t>>& covisible,
                                                 const GuidedCompletionOptions& options) {
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

  std::map<uint32_t, FreeKeypointGrid> grids;
  std::map<uint32_t, double> max_r2;
  for (const auto& [id, im] : rec->images) {
    if (!descriptors.count(id)) continue;
    const core::Camera& cam = rec->cameras.at(im.camera_id);
    grids.emplace(id, FreeKeypointGrid(im, cam, options.max_error_px));
    if (!max_r2.count(im.camera_id)) max_r2[im.camera_id] = MaxNormalisedRadius2(cam);
  }
  const double r2 = options.max_error_px * options.max_error_px;
  std::vector<Claim> claims;
  std::vector<int> decoys;
  for (const auto& entry : rec->points) {
    const uint32_t pid = entry.first;
    const auto& p = entry.second;  // not a structured binding: the search lambda below captures it (C++17)
    std::set<uint32_t> in_track, targets;
    for (const auto& t : p.track) in_track.insert(t.image_id);
    for (uint32_t id : in_track) {
      auto c = covisible.find(id);
      if (c != covisible.end()) targets.insert(c->second.begin(), c->second.end());
    }
    ++stats.points;
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
      const features::Descriptors& dj = *descriptors.at(id);
      // The most similar free keypoint within the radius of a location, by its smallest distance to the track.
      auto nearest = [&](const Eigen::Vector2d& at, uint32_t* kp) {
        int best = std::numeric_limits<int>::max();
        grids.at(id).Near(at, [&](uint32_t k) {
          if ((im.points2d[k] - at).squaredNorm() > r2) return;
          for (const auto& t : p.track) {
            auto d = descriptors.find(t.image_id);
            if (d == descriptors.end()) continue;
            const int s = SquaredDistance(*d->second, t.point2d_idx, dj, k);
            if (s < best) best = s, *kp = k;
          }
        });
        return best;
      };
      uint32_t kp = 0, decoy_kp = 0;
      const int best = nearest(uv, &kp);
      if (best != std::numeric_limits<int>::max()) {
        ++stats.candidates;
        claims.push_back({best, id, kp, pid});
      }
      // The decoy: the same search half an image away, where no keypoint is this point except by chance.
      const Eigen::Vector2d at(std::fmod(uv.x() + 0.5 * cam.width, double(cam.width)),
                               std::fmod(uv.y() + 0.5 * cam.height, double(cam.height)));
      const int decoy = nearest(at, &decoy_kp);
      if (decoy != std::numeric_limits<int>::max()) decoys.push_back(decoy);
    }
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
    ++stats.accepted;
  }
  return stats;
}

}  // namespace fmv3d::sfm
