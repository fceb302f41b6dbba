#include "fmv3d/align/global_registration.h"

#include <open3d/geometry/PointCloud.h>
#include <open3d/pipelines/registration/Feature.h>
#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <unordered_map>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/similarity.h"

namespace fmv3d::align {
namespace {

struct VoxelKeyHash {
  size_t operator()(const Eigen::Vector3i& k) const {
    return (size_t(uint32_t(k.x())) * 73856093u) ^ (size_t(uint32_t(k.y())) * 19349663u) ^
           (size_t(uint32_t(k.z())) * 83492791u);
  }
};
struct VoxelKeyEq {
  bool operator()(const Eigen::Vector3i& a, const Eigen::Vector3i& b) const { return a == b; }
};

std::vector<size_t> VoxelPick(const std::vector<Eigen::Vector3d>& pts, double voxel) {
  std::unordered_map<Eigen::Vector3i, size_t, VoxelKeyHash, VoxelKeyEq> seen;
  std::vector<size_t> pick;
  for (size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector3i key = (pts[i] / voxel).array().floor().cast<int>();
    if (seen.emplace(key, i).second) pick.push_back(i);
  }
  return pick;
}

io::OrientedPointCloud Transformed(const io::OrientedPointCloud& c, const core::Sim3& T) {
  io::OrientedPointCloud out = c;
  for (auto& p : out.positions) p = T.Apply(p);
  for (auto& n : out.normals) n = (T.q.cast<float>() * n);
  return out;
}

// Principal axes (columns, by decreasing extent) and centroid.
Eigen::Matrix3d PrincipalAxes(const std::vector<Eigen::Vector3d>& pts, Eigen::Vector3d* centroid) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : pts) c += p;
  c /= pts.size();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : pts) cov += (p - c) * (p - c).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  Eigen::Matrix3d axes;
  for (int k = 0; k < 3; ++k) axes.col(k) = es.eigenvectors().col(2 - k);
  if (axes.determinant() < 0) axes.col(2) = -axes.col(2);
  *centroid = c;
  return axes;
}

// The 24 rotations of the cube: signed permutation matrices with determinant +1.
std::vector<Eigen::Matrix3d> CubeRotations() {
  std::vector<Eigen::Matrix3d> out;
  const std::array<std::array<int, 3>, 6> perms = {{{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
  for (const auto& p : perms)
    for (int signs = 0; signs < 8; ++signs) {
      Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
      for (int r = 0; r < 3; ++r) M(r, p[r]) = (signs >> r) & 1 ? -1 : 1;
      if (M.determinant() > 0) out.push_back(M);
    }
  return out;
}

std::shared_ptr<open3d::pipelines::registration::Feature> Fpfh(const io::OrientedPointCloud& c, double voxel,
                                                               open3d::geometry::PointCloud* pc) {
  pc->points_ = c.positions;
  pc->EstimateNormals(open3d::geometry::KDTreeSearchParamHybrid(2 * voxel, 30));
  return open3d::pipelines::registration::ComputeFPFHFeature(*pc,
                                                             open3d::geometry::KDTreeSearchParamHybrid(5 * voxel, 100));
}

// Mutual nearest neighbours in feature space (brute force: a few thousand 33-dimensional FPFH vectors).
std::vector<std::pair<int, int>> MatchFeatures(const open3d::pipelines::registration::Feature& a,
                                               const open3d::pipelines::registration::Feature& b) {
  const Eigen::MatrixXd& A = a.data_;
  const Eigen::MatrixXd& B = b.data_;
  if (A.cols() == 0 || B.cols() == 0) return {};
  // |a − b|² = |a|² + |b|² − 2 a·b, all pairs at once.
  const Eigen::MatrixXd dot = A.transpose() * B;
  const Eigen::VectorXd na = A.colwise().squaredNorm().transpose(), nb = B.colwise().squaredNorm().transpose();
  std::vector<int> ab(A.cols()), ba(B.cols());
  for (int i = 0; i < A.cols(); ++i) {
    Eigen::Index j = 0;
    (nb - 2 * dot.row(i).transpose()).minCoeff(&j);
    ab[i] = static_cast<int>(j);
  }
  for (int j = 0; j < B.cols(); ++j) {
    Eigen::Index i = 0;
    (na - 2 * dot.col(j)).minCoeff(&i);
    ba[j] = static_cast<int>(i);
  }
  std::vector<std::pair<int, int>> out;
  for (int i = 0; i < A.cols(); ++i)
    if (ba[ab[i]] == i) out.push_back({i, ab[i]});
  return out;
}

}  // namespace

void GlobalRegistrationOptions::Check() const {
  if (!(scale_hint >= 0)) throw Error("global registration: scale_hint must be >= 0");
  if (max_points < 50) throw Error("global registration: max_points must be >= 50");
  if (!use_pca && !use_fpfh) throw Error("global registration: enable PCA or FPFH candidates");
  if (ransac_iterations < 1 || refine_iterations < 1 || refine_candidates < 1)
    throw Error("global registration: iterations must be >= 1");
}

io::OrientedPointCloud VoxelThin(const io::OrientedPointCloud& cloud, double voxel) {
  const auto pick = VoxelPick(cloud.positions, voxel);
  io::OrientedPointCloud out;
  out.positions.reserve(pick.size());
  for (size_t i : pick) {
    out.positions.push_back(cloud.positions[i]);
    if (cloud.has_normals()) out.normals.push_back(cloud.normals[i]);
    if (cloud.has_colors()) out.colors.push_back(cloud.colors[i]);
    if (cloud.has_visibility()) out.visibility.push_back(cloud.visibility[i]);
  }
  return out;
}

double VoxelForCount(const io::OrientedPointCloud& cloud, int target_points) {
  const Eigen::AlignedBox3d box = cloud.Bounds();
  double hi = std::max(box.diagonal().maxCoeff(), 1e-12), lo = hi * 1e-5;
  for (int it = 0; it < 30; ++it) {
    const double mid = std::sqrt(lo * hi);
    if (VoxelPick(cloud.positions, mid).size() > static_cast<size_t>(target_points))
      lo = mid;
    else
      hi = mid;
  }
  return hi;
}

GlobalRegistrationResult GlobalRegistration(const io::OrientedPointCloud& source, const io::OrientedPointCloud& target,
                                            const GlobalRegistrationOptions& options) {
  options.Check();
  if (source.size() < 10 || target.size() < 10)
    throw Error("global registration: need at least 10 points in each set (source " + std::to_string(source.size()) +
                ", target " + std::to_string(target.size()) + ")");
  GlobalRegistrationResult result;
  const double target_voxel = VoxelForCount(target, options.max_points);
  const io::OrientedPointCloud tgt = VoxelThin(target, target_voxel);
  const double s0 = options.scale_hint > 0 ? options.scale_hint
                    : options.estimate_scale
                        ? RmsRadius(target.positions) / std::max(RmsRadius(source.positions), 1e-300)
                        : 1.0;
  // The source in target units (scaled about the origin), thinned to a comparable count.
  core::Sim3 scale0;
  scale0.s = s0;
  const io::OrientedPointCloud src_scaled = Transformed(source, scale0);
  const io::OrientedPointCloud src = VoxelThin(src_scaled, VoxelForCount(src_scaled, options.max_points));
  const double voxel = target_voxel;
  result.voxel = voxel;
  const IcpTarget icp_target(tgt);

  std::vector<std::pair<core::Sim3, std::string>> candidates;  // src(target units) → target
  if (options.use_pca) {
    Eigen::Vector3d cs, ct;
    const Eigen::Matrix3d As = PrincipalAxes(src.positions, &cs), At = PrincipalAxes(tgt.positions, &ct);
    for (const Eigen::Matrix3d& M : CubeRotations()) {
      core::Sim3 c;
      const Eigen::Matrix3d R = At * M * As.transpose();
      c.q = Eigen::Quaterniond(R).normalized();
      c.t = ct - R * cs;
      candidates.push_back({c, "pca"});
    }
  }
  if (options.use_fpfh) {
    open3d::geometry::PointCloud ps, pt;
    const auto fs = Fpfh(src, voxel, &ps), ft = Fpfh(tgt, voxel, &pt);
    const auto pairs = MatchFeatures(*fs, *ft);
    std::vector<Eigen::Vector3d> a, b;
    for (const auto& [i, j] : pairs) {
      a.push_back(src.positions[i]);
      b.push_back(tgt.positions[j]);
    }
    geometry::SimilarityRansacOptions ro;
    ro.max_error = 2 * voxel;
    ro.max_iterations = options.ransac_iterations;
    ro.seed = options.seed;
    core::Sim3 sim;
    const int inliers = a.size() >= 3 ? geometry::EstimateSimilarityRansac(a, b, ro, &sim) : 0;
    spdlog::debug("global registration: {} FPFH matches, {} RANSAC inliers", pairs.size(), inliers);
    if (inliers >= 3) {
      if (!options.estimate_scale) sim.s = 1;  // keep the candidate rigid; ICP finishes it
      candidates.push_back({sim, "fpfh"});
    }
  }

  // Score every candidate cheaply (share of source points within 4 voxels of the target), then refine the
  // best few by a short rigid ICP and score them again at 2 voxels.
  const PointIndex& tindex = icp_target.index();
  auto score = [&](const core::Sim3& T, double radius) {
    size_t in = 0;
    for (const auto& p : src.positions) {
      double d2 = 0;
      if (tindex.Nearest(T.Apply(p), &d2) >= 0 && d2 <= radius * radius) ++in;
    }
    return double(in) / src.size();
  };
  std::vector<std::pair<double, size_t>> ranked;
  for (size_t i = 0; i < candidates.size(); ++i) ranked.push_back({-score(candidates[i].first, 4 * voxel), i});
  std::sort(ranked.begin(), ranked.end());
  ranked.resize(std::min<size_t>(ranked.size(), options.refine_candidates));
  IcpOptions ro;
  ro.estimate_scale = false;
  ro.max_iterations = options.refine_iterations;
  ro.trim_fraction = 0.8;
  ro.min_normal_cos = -1;  // normals of a wrong candidate say nothing; let geometry decide
  ro.tolerance = 1e-6;
  double best_score = -1;
  for (const auto& [neg, i] : ranked) {
    const auto& [cand, method] = candidates[i];
    core::Sim3 refined = cand;
    try {
      refined = ScaledIcp(src, icp_target, cand, ro).transform;
    } catch (const Error&) {
      continue;  // no overlap from this start
    }
    const double sc = score(refined, 2 * voxel);
    ++result.candidates;
    if (sc > best_score) {
      best_score = sc;
      result.transform = ComposeSim3(refined, scale0);
      result.method = method;
    }
  }
  if (best_score <= 0) throw Error("global registration: no candidate alignment overlaps the target");
  result.inlier_fraction = best_score;
  spdlog::debug("global registration: best {} candidate, {:.1f}% inliers of {} candidates", result.method,
                100 * best_score, result.candidates);
  return result;
}

}  // namespace fmv3d::align
