// The intrinsics' marginal covariance from the reduced camera system, against the dense inverse of the whole
// Jacobian's normal matrix on small bundle adjustment problems built here (the same residual, loss and manifolds as the
// BA).
#include "fmv3d/sfm/intrinsics_covariance.h"

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <array>
#include <deque>
#include <map>
#include <memory>
#include <random>

#include "fmv3d/geometry/reprojection_error.h"
#include "fmv3d/sfm/synthetic_correspondences.h"

namespace fmv3d::sfm {
namespace {

// A bundle adjustment problem over a reconstruction: every observation a residual (Cauchy loss at 1 px), poses on
// the quaternion manifold, the intrinsics f, u0, v0, k1, k2 free (aspect and tangential held). The first image's
// pose and the second's translation are held: the gauge.
class TinyBa {
 public:
  explicit TinyBa(const core::Reconstruction& rec) : loss_(1.0), problem_(Options()) {
    for (const auto& [cid, cam] : rec.cameras) {
      const auto p = cam.Params();
      intr_.push_back(std::make_unique<std::array<double, core::kNumIntrinsics>>());
      std::copy(p.begin(), p.end(), intr_.back()->begin());
      cam_index_[cid] = intr_.size() - 1;
    }
    for (const auto& [id, im] : rec.images) {
      auto& b = poses_[id];
      b = {im.pose.q.x(), im.pose.q.y(), im.pose.q.z(), im.pose.q.w(), im.pose.t.x(), im.pose.t.y(), im.pose.t.z()};
    }
    for (const auto& [pid, p] : rec.points) {
      points_.push_back({p.xyz.x(), p.xyz.y(), p.xyz.z()});
      for (const auto& el : p.track) {
        const auto& im = rec.images.at(el.image_id);
        costs_.emplace_back(im.points2d[el.point2d_idx]);
        double* intr = intr_[cam_index_.at(im.camera_id)]->data();
        double* pose = poses_.at(el.image_id).data();
        problem_.AddResidualBlock(&costs_.back(), &loss_, intr, pose, pose + 4, points_.back().data());
      }
    }
    for (auto& [id, b] : poses_) problem_.SetManifold(b.data(), &quaternion_);
    problem_.SetParameterBlockConstant(poses_.begin()->second.data());
    problem_.SetParameterBlockConstant(poses_.begin()->second.data() + 4);
    problem_.SetParameterBlockConstant(std::next(poses_.begin())->second.data() + 4);
    for (auto& in : intr_) problem_.SetManifold(in->data(), &held_);
  }

  ceres::Problem& problem() { return problem_; }
  std::vector<const double*> Points() {
    std::vector<const double*> out;
    for (auto& p : points_) out.push_back(p.data());
    return out;
  }
  std::vector<const double*> Intrinsics() {
    std::vector<const double*> out;
    for (auto& in : intr_) out.push_back(in->data());
    return out;
  }
  // One more point with a single observation in the first image: its depth is undetermined.
  void AddSingleObservationPoint(const core::Reconstruction& rec) {
    const auto& im = rec.images.begin()->second;
    points_.push_back({0.1, 0.2, 0.3});
    const Eigen::Vector2d uv = rec.cameras.at(im.camera_id).Project(im.pose.Transform(Eigen::Vector3d(0.1, 0.2, 0.3)));
    costs_.emplace_back(uv + Eigen::Vector2d(0.3, -0.2));
    double* pose = poses_.at(im.id).data();
    problem_.AddResidualBlock(&costs_.back(), &loss_, intr_[cam_index_.at(im.camera_id)]->data(), pose, pose + 4,
                              points_.back().data());
  }

 private:
  static ceres::Problem::Options Options() {
    ceres::Problem::Options o;
    o.cost_function_ownership = o.loss_function_ownership = o.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    return o;
  }
  std::vector<std::unique_ptr<std::array<double, core::kNumIntrinsics>>> intr_;
  std::map<uint32_t, size_t> cam_index_;
  std::map<uint32_t, std::array<double, 7>> poses_;
  std::deque<std::array<double, 3>> points_;
  std::deque<geometry::AnalyticReprojectionError> costs_;
  ceres::CauchyLoss loss_;
  ceres::EigenQuaternionManifold quaternion_;
  ceres::SubsetManifold held_{core::kNumIntrinsics, {core::kAspect, core::kP1, core::kP2}};
  ceres::Problem problem_;
};

// The reference: the whole Jacobian from Ceres (loss applied, tangent spaces, held blocks left out), its normal
// matrix inverted densely, each intrinsics block mapped back to ambient coordinates (held parameters zero). Dense
// and independent of the Schur reduction under test; computed by our own Eigen code, since ceres::Covariance's
// dense SVD aborts under AddressSanitizer (an aligned-allocation mismatch between libceres and sanitized code).
std::vector<Eigen::MatrixXd> DenseCovariance(ceres::Problem* problem, const std::vector<const double*>& blocks) {
  std::vector<double*> all;
  problem->GetParameterBlocks(&all);
  ceres::Problem::EvaluateOptions eo;
  std::map<const double*, int> column;  // the tangent columns of each free block
  int columns = 0;
  for (double* b : all) {
    if (problem->IsParameterBlockConstant(b)) continue;
    eo.parameter_blocks.push_back(b);
    column[b] = columns;
    columns += problem->ParameterBlockTangentSize(b);
  }
  eo.apply_loss_function = true;
  ceres::CRSMatrix crs;
  if (!problem->Evaluate(eo, nullptr, nullptr, nullptr, &crs)) return {};
  Eigen::MatrixXd jacobian = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r)
    for (int k = crs.rows[r]; k < crs.rows[r + 1]; ++k) jacobian(r, crs.cols[k]) = crs.values[k];
  const Eigen::MatrixXd normal = jacobian.transpose() * jacobian;
  const Eigen::FullPivLU<Eigen::MatrixXd> lu(normal);
  if (!lu.isInvertible()) return {};
  const Eigen::MatrixXd inverse = lu.inverse();
  std::vector<Eigen::MatrixXd> out;
  for (const double* b : blocks) {
    const ceres::Manifold* m = problem->GetManifold(b);
    Eigen::Matrix<double, core::kNumIntrinsics, Eigen::Dynamic, Eigen::RowMajor> lift(core::kNumIntrinsics,
                                                                                      m->TangentSize());
    EXPECT_TRUE(m->PlusJacobian(b, lift.data()));
    const int t = m->TangentSize();
    out.emplace_back(lift * inverse.block(column.at(b), column.at(b), t, t) * lift.transpose());
  }
  return out;
}

// Largest difference relative to the standard deviations involved: |A_ij − B_ij| / sqrt(B_ii B_jj); held rows
// must be zero in both.
double MaxScaledDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  double worst = 0;
  for (int i = 0; i < b.rows(); ++i)
    for (int j = 0; j < b.cols(); ++j) {
      const double s = std::sqrt(b(i, i) * b(j, j));
      worst = std::max(worst, s > 0 ? std::abs(a(i, j) - b(i, j)) / s : std::abs(a(i, j)));
    }
  return worst;
}

// A small orbit with two cameras (odd and even images) and noisy observations.
core::Reconstruction TwoCameraOrbit() {
  SyntheticSceneOptions so;
  so.num_cameras = 8;
  so.num_points = 150;
  so.orbit_arc_deg = 90;
  so.k2 = 0.02;
  so.noise_px = 0.7;
  core::Reconstruction rec = TrueModelWithObservations(so);
  core::Camera second = rec.cameras.at(1);  // the same lens, its own parameter block
  second.id = 2;
  rec.cameras[2] = second;
  for (auto& [id, im] : rec.images)
    if (id % 2 == 0) im.camera_id = 2;
  return rec;
}

TEST(IntrinsicsCovariance, MatchesDenseInverseWithRobustLoss) {
  const core::Reconstruction rec = TwoCameraOrbit();
  ASSERT_GE(rec.points.size(), 40u);
  TinyBa ba(rec);
  const auto ours = MarginalCovariance(ba.problem(), ba.Points(), ba.Intrinsics());
  const auto reference = DenseCovariance(&ba.problem(), ba.Intrinsics());
  ASSERT_TRUE(ours.has_value());
  ASSERT_EQ(reference.size(), 2u);
  for (int c = 0; c < 2; ++c) {
    const Eigen::MatrixXd& m = (*ours)[c];
    ASSERT_EQ(m.rows(), core::kNumIntrinsics);
    for (int k : {core::kF, core::kU0, core::kV0, core::kK1, core::kK2}) EXPECT_GT(m(k, k), 0) << k;
    for (int k : {core::kAspect, core::kP1, core::kP2}) EXPECT_EQ(m.row(k).norm() + m.col(k).norm(), 0) << k;
    EXPECT_LT(MaxScaledDifference(m, reference[c]), 1e-6) << "camera " << c << "\nours\n"
                                                          << m << "\nreference\n"
                                                          << reference[c];
  }
}

TEST(IntrinsicsCovariance, PointWithOneObservationIsPseudoInverted) {
  // A point seen once carries no information about the cameras (it absorbs its two residuals): the covariance is
  // that of the problem without it, where the whole Jacobian (Ceres') is rank-deficient.
  const core::Reconstruction rec = TwoCameraOrbit();
  TinyBa ba(rec);
  const auto before = MarginalCovariance(ba.problem(), ba.Points(), ba.Intrinsics());
  ba.AddSingleObservationPoint(rec);
  const auto after = MarginalCovariance(ba.problem(), ba.Points(), ba.Intrinsics());
  ASSERT_TRUE(before && after);
  for (int c = 0; c < 2; ++c) EXPECT_LT(MaxScaledDifference((*after)[c], (*before)[c]), 1e-9);
}

// Six images from one height over a scene with 2 m of relief, exact observations; tilt_deg = 0: straight down.
core::Reconstruction GridFlight(double tilt_deg) {
  core::Reconstruction rec;
  core::Camera cam = core::Camera::Pinhole(1000, 800, 900);
  cam.k1 = -0.05;
  cam.k2 = 0.01;
  rec.cameras[1] = cam;
  const Eigen::Quaterniond down(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()));  // camera z towards −Z
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  for (uint32_t id = 1; id <= 6; ++id) {
    core::Image im;
    im.id = id;
    im.camera_id = 1;
    const int row = static_cast<int>(id - 1) / 3, column = static_cast<int>(id - 1) % 3;  // a 3-wide grid
    const Eigen::Vector3d centre(2.0 * column, 2.0 * row, 10);
    const double tilt = tilt_deg * M_PI / 180 * (id % 2 ? 1 : -1);
    const Eigen::Vector3d axis = id <= 3 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    im.pose.q = Eigen::AngleAxisd(tilt, axis) * down;
    im.pose.t = -(im.pose.q * centre);
    rec.images[id] = im;
  }
  for (uint64_t pid = 1; pid <= 80; ++pid) {
    core::Point3D p;
    p.id = pid;
    p.xyz = Eigen::Vector3d{2 + 4 * u(rng), 1 + 3 * u(rng), 2 * u(rng)};
    for (auto& [id, im] : rec.images) {
      const Eigen::Vector2d uv = cam.Project(im.pose.Transform(p.xyz));
      if (uv.x() < 0 || uv.y() < 0 || uv.x() > cam.width || uv.y() > cam.height) continue;
      p.track.push_back({id, static_cast<uint32_t>(im.points2d.size())});
      im.points2d.push_back(uv);
      im.point3d_ids.push_back(static_cast<int64_t>(pid));
    }
    if (p.track.size() >= 2) rec.points[pid] = p;
  }
  return rec;
}

TEST(IntrinsicsCovariance, FocalOfNadirImagesIsRankDeficient) {
  // Every image looking straight down: stretching all heights about the held images' (points and free cameras
  // alike) by s scales every normalised image coordinate by 1/s, which f·s, k1·s² and k2·s⁴ undo, so nothing is
  // returned. Tilted images break the tie, and the result then agrees with the dense reference.
  const core::Reconstruction nadir = GridFlight(0);
  ASSERT_GE(nadir.points.size(), 40u);
  TinyBa straight(nadir);
  EXPECT_FALSE(MarginalCovariance(straight.problem(), straight.Points(), straight.Intrinsics()).has_value());

  const core::Reconstruction tilted = GridFlight(15);
  ASSERT_GE(tilted.points.size(), 40u);
  TinyBa oblique(tilted);
  const auto ours = MarginalCovariance(oblique.problem(), oblique.Points(), oblique.Intrinsics());
  const auto reference = DenseCovariance(&oblique.problem(), oblique.Intrinsics());
  ASSERT_TRUE(ours.has_value());
  ASSERT_EQ(reference.size(), 1u);
  EXPECT_LT(MaxScaledDifference((*ours)[0], reference[0]), 1e-6);
}

}  // namespace
}  // namespace fmv3d::sfm
