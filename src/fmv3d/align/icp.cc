#include "fmv3d/align/icp.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/core/threading.h"
#include "fmv3d/geometry/similarity.h"

namespace fmv3d::align {
namespace {

double Intensity(const io::Rgb8& c) { return (double(c[0]) + double(c[1]) + double(c[2])) / (3.0 * 255.0); }

// The similarity update is parameterised about the centroid c of the matched source points, so that rotation
// and scale barely couple with translation: X'' = c + e^σ·R(ω)·(X' − c) + τ, x = (ω[3], τ[3], σ).
template <typename T>
void MoveCentred(const T* x, const Eigen::Vector3d& p_centred, T* out) {
  const T p[3] = {T(p_centred.x()), T(p_centred.y()), T(p_centred.z())};
  T rp[3];
  ceres::AngleAxisRotatePoint(x, p, rp);
  const T s = ceres::exp(x[6]);
  for (int k = 0; k < 3; ++k) out[k] = s * rp[k] + x[3 + k];
}

// Chen–Medioni: signed distance of the moved source point to the target's tangent plane, in target spacings,
// times √weight (normal agreement and the geometric share 1 − λ).
struct PlaneResidual {
  Eigen::Vector3d p, q, n;  // p, q relative to the centroid
  double w;
  template <typename T>
  bool operator()(const T* x, T* r) const {
    T m[3];
    MoveCentred(x, p, m);
    r[0] = T(w) * (T(n.x()) * (m[0] - T(q.x())) + T(n.y()) * (m[1] - T(q.y())) + T(n.z()) * (m[2] - T(q.z())));
    return true;
  }
};

// Park et al.: the target intensity continued along its tangent plane, I_q + g_q·(X'' − q) (g_q ⊥ n_q, so the
// projection onto the plane drops out), compared with the source point's intensity.
struct ColourResidual {
  Eigen::Vector3d p, q, g;
  double ip, iq, w;
  template <typename T>
  bool operator()(const T* x, T* r) const {
    T m[3];
    MoveCentred(x, p, m);
    const T predicted =
        T(iq) + T(g.x()) * (m[0] - T(q.x())) + T(g.y()) * (m[1] - T(q.y())) + T(g.z()) * (m[2] - T(q.z()));
    r[0] = T(w) * (T(ip) - predicted);
    return true;
  }
};

ceres::LossFunction* MakeLoss(RobustLoss loss, double scale) {
  switch (loss) {
    case RobustLoss::kHuber:
      return new ceres::HuberLoss(scale);
    case RobustLoss::kCauchy:
      return new ceres::CauchyLoss(scale);
    case RobustLoss::kNone:
      break;
  }
  return nullptr;
}

}  // namespace

RobustLoss ParseRobustLoss(const std::string& name) {
  if (name == "none") return RobustLoss::kNone;
  if (name == "huber") return RobustLoss::kHuber;
  if (name == "cauchy") return RobustLoss::kCauchy;
  throw Error("unknown robust loss '" + name + "' (expected none, huber or cauchy)");
}

void IcpOptions::Check() const {
  if (!(max_correspondence_distance >= 0)) throw Error("ICP: max_correspondence_distance must be >= 0");
  if (!(trim_fraction > 0 && trim_fraction <= 1)) throw Error("ICP: trim_fraction must be in (0, 1]");
  if (!(min_normal_cos >= -1 && min_normal_cos < 1)) throw Error("ICP: min_normal_cos must be in [-1, 1)");
  if (!(colour_weight >= 0 && colour_weight < 1)) throw Error("ICP: colour_weight must be in [0, 1)");
  if (!(loss_scale >= 0)) throw Error("ICP: loss_scale must be >= 0");
  if (max_iterations < 1) throw Error("ICP: max_iterations must be >= 1");
  if (!(tolerance > 0)) throw Error("ICP: tolerance must be > 0");
  if (max_source_points < 0) throw Error("ICP: max_source_points must be >= 0");
  if (normal_neighbours < 3) throw Error("ICP: normal_neighbours must be >= 3");
  if (lm_iterations < 1) throw Error("ICP: lm_iterations must be >= 1");
}

core::Sim3 ComposeSim3(const core::Sim3& a, const core::Sim3& b) {
  core::Sim3 c;
  c.s = a.s * b.s;
  c.q = (a.q * b.q).normalized();
  c.t = a.s * (a.q * b.t) + a.t;
  return c;
}

IcpTarget::IcpTarget(const io::OrientedPointCloud& cloud, int normal_neighbours, bool with_colour)
    : points_(cloud.positions), index_(cloud.positions) {
  if (points_.size() < 3) throw Error("ICP target: need at least 3 points, got " + std::to_string(points_.size()));
  cloud.Validate();
  if (cloud.has_normals()) {
    normals_.resize(points_.size());
    for (size_t i = 0; i < points_.size(); ++i) {
      const Eigen::Vector3d n = cloud.normals[i].cast<double>();
      normals_[i] = n.norm() > 1e-12 ? n.normalized() : Eigen::Vector3d::UnitZ();
    }
    normals_oriented_ = true;
  } else {
    normals_ = EstimateNormals(points_, index_, normal_neighbours);
  }
  spacing_ = MedianSpacing(points_, index_);
  radius_ = RmsRadius(points_);
  if (!(spacing_ > 0)) spacing_ = std::max(radius_ * 1e-3, 1e-12);
  if (with_colour && cloud.has_colors()) {
    intensity_.resize(points_.size());
    for (size_t i = 0; i < points_.size(); ++i) intensity_[i] = Intensity(cloud.colors[i]);
    gradients_.assign(points_.size(), Eigen::Vector3d::Zero());
    // Least-squares gradient in the tangent plane from the neighbours' intensity differences.
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points_.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
      std::vector<int> nn;
      std::vector<double> d2;
      for (size_t i = r.begin(); i < r.end(); ++i) {
        index_.Knn(points_[i], normal_neighbours, &nn, &d2);
        const Eigen::Vector3d& n = normals_[i];
        const Eigen::Vector3d u = n.unitOrthogonal(), v = n.cross(u);
        Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
        Eigen::Vector2d b = Eigen::Vector2d::Zero();
        for (int j : nn) {
          if (static_cast<size_t>(j) == i) continue;
          const Eigen::Vector3d d = points_[j] - points_[i];
          const Eigen::Vector2d a(d.dot(u), d.dot(v));
          A += a * a.transpose();
          b += a * (intensity_[j] - intensity_[i]);
        }
        if (nn.size() < 4) continue;
        A += Eigen::Matrix2d::Identity() * 1e-9 * (A.trace() + 1e-30);
        const Eigen::Vector2d g = A.ldlt().solve(b);
        if (g.allFinite()) gradients_[i] = g.x() * u + g.y() * v;
      }
    });
  }
}

core::Sim3 PointToPointEstimation::Update(const IcpSource& source, const IcpTarget& target,
                                          const std::vector<Correspondence>& corr, bool estimate_scale) const {
  std::vector<Eigen::Vector3d> a, b;
  std::vector<double> w;
  a.reserve(corr.size());
  b.reserve(corr.size());
  w.reserve(corr.size());
  for (const auto& c : corr) {
    a.push_back(source.points[c.source]);
    b.push_back(target.points()[c.target]);
    w.push_back(c.weight);
  }
  core::Sim3 sim;
  if (!geometry::EstimateSimilarity(a, b, w, estimate_scale, &sim)) return core::Sim3();
  return sim;
}

double PointToPointEstimation::Residual(const IcpSource& source, const IcpTarget& target,
                                        const Correspondence& c) const {
  return (source.points[c.source] - target.points()[c.target]).norm();
}

double PointToPlaneEstimation::Residual(const IcpSource& source, const IcpTarget& target,
                                        const Correspondence& c) const {
  return target.normals()[c.target].dot(source.points[c.source] - target.points()[c.target]);
}

core::Sim3 PointToPlaneEstimation::Update(const IcpSource& source, const IcpTarget& target,
                                          const std::vector<Correspondence>& corr, bool estimate_scale) const {
  if (corr.size() < 7) return core::Sim3();
  const double unit = target.spacing();
  const bool colour = colour_weight_ > 0 && target.has_colour() && !source.intensity.empty();
  const double wg = std::sqrt(colour ? 1 - colour_weight_ : 1.0) / unit;
  const double wc = colour ? std::sqrt(colour_weight_) : 0;

  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (const auto& c : corr) {
    centroid += c.weight * source.points[c.source];
    wsum += c.weight;
  }
  centroid /= wsum;

  double scale = loss_scale_;
  if (loss_ != RobustLoss::kNone && scale <= 0) {
    std::vector<double> r(corr.size());
    for (size_t i = 0; i < corr.size(); ++i) r[i] = std::abs(Residual(source, target, corr[i])) / unit;
    scale = std::max(2.5 * core::RobustSigma(r), 1e-6);
  }

  double x[7] = {0, 0, 0, 0, 0, 0, 0};
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  // One loss object shared by all blocks: Ceres reference-counts owned losses and frees each once.
  ceres::LossFunction* loss = MakeLoss(loss_, scale);
  // Colour residuals are intensities in [0, 1]: a tenth of the range is where a difference stops being
  // shading noise and starts being a different surface (or a shadow).
  ceres::LossFunction* colour_loss = colour ? MakeLoss(loss_, 0.1) : nullptr;
  for (const auto& c : corr) {
    const Eigen::Vector3d p = source.points[c.source] - centroid;
    const Eigen::Vector3d q = target.points()[c.target] - centroid;
    const double sw = std::sqrt(c.weight);
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PlaneResidual, 1, 7>(
                                 new PlaneResidual{p, q, target.normals()[c.target], sw * wg}),
                             loss, x);
    if (colour) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<ColourResidual, 1, 7>(new ColourResidual{
              p, q, target.gradients()[c.target], source.intensity[c.source], target.intensity()[c.target], sw * wc}),
          colour_loss, x);
    }
  }
  if (!estimate_scale) problem.SetManifold(x, new ceres::SubsetManifold(7, {6}));

  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  so.max_num_iterations = lm_iterations_;
  so.function_tolerance = 1e-14;
  so.gradient_tolerance = 1e-16;
  so.parameter_tolerance = 1e-14;
  so.num_threads = core::NumThreads();
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (!summary.IsSolutionUsable()) return core::Sim3();

  // X'' = c + s·R·(X' − c) + τ  =  s·R·X' + (c + τ − s·R·c).
  core::Sim3 delta;
  delta.s = std::exp(x[6]);
  const Eigen::Vector3d aa(x[0], x[1], x[2]);
  const double angle = aa.norm();
  delta.q = angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, aa / angle)) : Eigen::Quaterniond::Identity();
  delta.t = centroid + Eigen::Vector3d(x[3], x[4], x[5]) - delta.s * (delta.q * centroid);
  return delta;
}

namespace {

struct Matching {
  std::vector<Correspondence> kept;
  double max_distance = 0;
};

// Nearest target point for every source point, then the distance, normal and trimming filters.
Matching FindCorrespondences(const IcpSource& src, const IcpTarget& target, const IcpOptions& o, int iteration) {
  const size_t n = src.points.size();
  std::vector<int> nn(n, -1);
  std::vector<double> dist(n, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 512), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) {
      double d2 = 0;
      nn[i] = target.index().Nearest(src.points[i], &d2);
      dist[i] = std::sqrt(d2);
    }
  });
  Matching m;
  m.max_distance = o.max_correspondence_distance;
  if (m.max_distance <= 0) {
    if (iteration == 0) {
      m.max_distance = std::numeric_limits<double>::infinity();
    } else {
      std::vector<double> d(dist);
      m.max_distance = std::max(3.0 * core::RobustSigma(d), 3.0 * target.spacing());
    }
  }
  const bool use_normals = !src.normals.empty();
  const bool oriented = src.normals_oriented && target.normals_oriented();
  std::vector<std::pair<double, Correspondence>> cand;
  cand.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    if (nn[i] < 0 || !(dist[i] <= m.max_distance)) continue;
    double w = 1;
    if (use_normals) {
      double c = src.normals[i].dot(target.normals()[nn[i]]);
      if (!oriented) c = std::abs(c);
      if (c < o.min_normal_cos) continue;
      w = std::max(c, 1e-3);
    }
    cand.push_back({dist[i], Correspondence{static_cast<int>(i), nn[i], w}});
  }
  const size_t keep = static_cast<size_t>(std::ceil(o.trim_fraction * cand.size()));
  if (keep < cand.size()) {
    std::nth_element(cand.begin(), cand.begin() + keep, cand.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    cand.resize(keep);
  }
  std::sort(cand.begin(), cand.end(), [](const auto& a, const auto& b) { return a.second.source < b.second.source; });
  m.kept.reserve(cand.size());
  for (const auto& c : cand) m.kept.push_back(c.second);
  return m;
}

void MoveSource(const io::OrientedPointCloud& cloud, const std::vector<int>& pick,
                const std::vector<Eigen::Vector3d>& normals, const core::Sim3& T, IcpSource* out) {
  out->points.resize(pick.size());
  if (!normals.empty()) out->normals.resize(pick.size());
  for (size_t i = 0; i < pick.size(); ++i) {
    out->points[i] = T.Apply(cloud.positions[pick[i]]);
    if (!normals.empty()) out->normals[i] = T.q * normals[i];
  }
}

double Rms(const SimilarityEstimation& est, const IcpSource& src, const IcpTarget& target,
           const std::vector<Correspondence>& corr) {
  if (corr.empty()) return 0;
  double s = 0;
  for (const auto& c : corr) s += std::pow(est.Residual(src, target, c), 2);
  return std::sqrt(s / corr.size());
}

}  // namespace

IcpResult ScaledIcp(const io::OrientedPointCloud& source, const IcpTarget& target, const core::Sim3& initial,
                    const IcpOptions& options, const SimilarityEstimation* estimation) {
  options.Check();
  if (source.empty()) throw Error("ICP: the source point set is empty");
  source.Validate();
  PointToPlaneEstimation default_estimation(options.loss, options.loss_scale, options.colour_weight,
                                            options.lm_iterations);
  const SimilarityEstimation& est = estimation ? *estimation : default_estimation;

  const std::vector<int> pick = EvenSubsample(source.size(), options.max_source_points);
  // Source normals in the source frame (rotated with the estimate each iteration).
  std::vector<Eigen::Vector3d> normals;
  bool oriented = false;
  if (source.has_normals()) {
    normals.resize(pick.size());
    for (size_t i = 0; i < pick.size(); ++i) {
      const Eigen::Vector3d n = source.normals[pick[i]].cast<double>();
      normals[i] = n.norm() > 1e-12 ? n.normalized() : Eigen::Vector3d::UnitZ();
    }
    oriented = true;
  } else {
    std::vector<Eigen::Vector3d> pts(pick.size());
    for (size_t i = 0; i < pick.size(); ++i) pts[i] = source.positions[pick[i]];
    if (pts.size() >= 3) normals = EstimateNormals(pts, PointIndex(pts), options.normal_neighbours);
  }
  IcpSource src;
  src.normals_oriented = oriented;
  if (options.colour_weight > 0 && source.has_colors()) {
    src.intensity.resize(pick.size());
    for (size_t i = 0; i < pick.size(); ++i) src.intensity[i] = Intensity(source.colors[pick[i]]);
  }

  IcpResult result;
  result.estimation = est.Name();
  result.source_points = pick.size();
  core::Sim3 T = initial;
  double last_move = std::numeric_limits<double>::infinity();
  for (int it = 0; it < options.max_iterations; ++it) {
    MoveSource(source, pick, normals, T, &src);
    const Matching m = FindCorrespondences(src, target, options, it);
    if (m.kept.size() < 10)
      throw Error("ICP: only " + std::to_string(m.kept.size()) +
                  " correspondences between the point sets at this start (no overlap?)");
    if (it == 0) result.initial_rmse = Rms(est, src, target, m.kept);
    const core::Sim3 delta = est.Update(src, target, m.kept, options.estimate_scale);
    T = ComposeSim3(delta, T);
    result.iterations = it + 1;
    // Largest displacement of a source point by this update, bounded through the centroid and radius.
    Eigen::Vector3d c;
    const double radius = std::max(RmsRadius(src.points, &c), 1e-300);
    const double move = (delta.Apply(c) - c).norm() +
                        (2 * std::asin(std::min(1.0, delta.q.vec().norm())) + std::abs(delta.s - 1)) * 3 * radius;
    spdlog::debug("ICP {:2d}: {} pairs, max distance {:.4g}, rmse {:.6g}, update {:.3g} of radius", it, m.kept.size(),
                  m.max_distance, Rms(est, src, target, m.kept), move / radius);
    // Converged: the update is below the tolerance, or — at the noise floor, where nearest neighbours flip
    // between equally good partners and the estimate jitters instead of shrinking — small (1e-5 of the
    // radius) and no longer at least halving.
    const bool stalled = it >= 3 && move < 1e-5 * radius && move > 0.5 * last_move;
    last_move = move;
    if (move < options.tolerance * radius || stalled) {
      result.converged = true;
      break;
    }
  }
  MoveSource(source, pick, normals, T, &src);
  const Matching m = FindCorrespondences(src, target, options, result.iterations);
  result.transform = T;
  result.correspondences = m.kept.size();
  result.fitness = pick.empty() ? 0 : double(m.kept.size()) / pick.size();
  result.rmse = Rms(est, src, target, m.kept);
  double s = 0;
  for (const auto& c : m.kept) s += (src.points[c.source] - target.points()[c.target]).squaredNorm();
  result.rmse_point = m.kept.empty() ? 0 : std::sqrt(s / m.kept.size());
  return result;
}

}  // namespace fmv3d::align
