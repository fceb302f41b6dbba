#include "fmv3d/geometry/two_view.h"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"

namespace fmv3d::geometry {
namespace {

template <typename T>
T SampsonResidual(const Eigen::Matrix<T, 3, 3>& M, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Matrix<T, 3, 1> x1(T(a.x()), T(a.y()), T(1)), x2(T(b.x()), T(b.y()), T(1));
  const Eigen::Matrix<T, 3, 1> Mx1 = M * x1;
  const Eigen::Matrix<T, 3, 1> Mtx2 = M.transpose() * x2;
  const T num = x2.dot(Mx1);
  const T den = Mx1(0) * Mx1(0) + Mx1(1) * Mx1(1) + Mtx2(0) * Mtx2(0) + Mtx2(1) * Mtx2(1);
  // den > 0 for any non-degenerate F; guard against a division by zero at a degenerate start.
  return num / ceres::sqrt(den + T(1e-30));
}

// Hartley normalisation: centroid to the origin, mean distance sqrt(2).
Eigen::Matrix3d NormalisingTransform(const Points2& x) {
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const auto& p : x) c += p;
  c /= static_cast<double>(x.size());
  double d = 0;
  for (const auto& p : x) d += (p - c).norm();
  d /= static_cast<double>(x.size());
  const double s = d > 0 ? std::sqrt(2.0) / d : 1.0;
  Eigen::Matrix3d T;
  T << s, 0, -s * c.x(), 0, s, -s * c.y(), 0, 0, 1;
  return T;
}

Eigen::Vector2d Apply(const Eigen::Matrix3d& T, const Eigen::Vector2d& p) {
  return (T * p.homogeneous()).hnormalized();
}

struct SampsonECost {
  Eigen::Vector2d n1, n2;
  double focal;
  template <typename T>
  bool operator()(const T* q, const T* t, T* residual) const {
    const Eigen::Quaternion<T> Q(q[3], q[0], q[1], q[2]);
    Eigen::Matrix<T, 3, 3> tx;
    tx << T(0), -t[2], t[1], t[2], T(0), -t[0], -t[1], t[0], T(0);
    const Eigen::Matrix<T, 3, 3> E = tx * Q.toRotationMatrix();
    residual[0] = T(focal) * SampsonResidual<T>(E, n1, n2);
    return true;
  }
};

ceres::Solver::Options SmallSolverOptions() {
  ceres::Solver::Options o;
  o.linear_solver_type = ceres::DENSE_QR;
  o.max_num_iterations = 50;
  o.num_threads = 1;
  o.logging_type = ceres::SILENT;
  o.minimizer_progress_to_stdout = false;
  o.function_tolerance = 1e-10;
  o.parameter_tolerance = 1e-10;
  return o;
}

std::vector<cv::Point2d> ToCv(const Points2& x) {
  std::vector<cv::Point2d> out(x.size());
  for (size_t i = 0; i < x.size(); ++i) out[i] = {x[i].x(), x[i].y()};
  return out;
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& t) {
  Eigen::Matrix3d m;
  m << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  return m;
}

int CountInliers(const Eigen::Matrix3d& M, const Points2& x1, const Points2& x2, double thr_sq, double scale_sq,
                 std::vector<char>* mask) {
  mask->assign(x1.size(), 0);
  int n = 0;
  for (size_t i = 0; i < x1.size(); ++i) {
    if (SampsonErrorSq(M, x1[i], x2[i]) * scale_sq <= thr_sq) {
      (*mask)[i] = 1;
      ++n;
    }
  }
  return n;
}

void Select(const Points2& x1, const Points2& x2, const std::vector<char>& mask, Points2* y1, Points2* y2) {
  y1->clear();
  y2->clear();
  for (size_t i = 0; i < mask.size(); ++i)
    if (mask[i]) {
      y1->push_back(x1[i]);
      y2->push_back(x2[i]);
    }
}

}  // namespace

double SampsonErrorSq(const Eigen::Matrix3d& M, const Eigen::Vector2d& x1, const Eigen::Vector2d& x2) {
  const double r = SampsonResidual<double>(M, x1, x2);
  return r * r;
}

bool EightPointFundamental(const Points2& x1, const Points2& x2, Eigen::Matrix3d* F) {
  if (x1.size() < 8 || x1.size() != x2.size()) return false;
  const Eigen::Matrix3d T1 = NormalisingTransform(x1), T2 = NormalisingTransform(x2);
  // Accumulate A^T A (9x9) rather than A (n x 9): the same null vector, constant memory.
  Eigen::Matrix<double, 9, 9> AtA = Eigen::Matrix<double, 9, 9>::Zero();
  for (size_t i = 0; i < x1.size(); ++i) {
    const Eigen::Vector2d a = Apply(T1, x1[i]), b = Apply(T2, x2[i]);
    Eigen::Matrix<double, 9, 1> row;
    row << b.x() * a.x(), b.x() * a.y(), b.x(), b.y() * a.x(), b.y() * a.y(), b.y(), a.x(), a.y(), 1;
    AtA.noalias() += row * row.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eig(AtA);
  if (eig.info() != Eigen::Success) return false;
  // Degenerate when the null space is not one-dimensional.
  if (eig.eigenvalues()(1) <= 1e-12 * std::max(1.0, eig.eigenvalues()(8))) return false;
  const Eigen::Matrix<double, 9, 1> f = eig.eigenvectors().col(0);
  Eigen::Matrix3d Fn;
  Fn << f(0), f(1), f(2), f(3), f(4), f(5), f(6), f(7), f(8);
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(Fn, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d s = svd.singularValues();
  s(2) = 0;
  Fn = svd.matrixU() * s.asDiagonal() * svd.matrixV().transpose();
  *F = T2.transpose() * Fn * T1;
  const double norm = F->norm();
  if (!(norm > 0) || !F->allFinite()) return false;
  *F /= norm;
  return true;
}

// Levenberg–Marquardt with analytic derivatives (Ceres autodiff through the rotation parametrisation cost 2/3
// of the whole match stage on video). Fn = U diag(1, s, 0) V^T in Hartley-normalised coordinates y = T x;
// updates U <- U exp([wu]x), V <- V exp([wv]x), s <- s + ds. With T = [k 0 -k c; 0 k -k c'; 0 0 1], the pixel
// Sampson residual is r = y2^T Fn y1 / sqrt(k2² |(Fn y1)_01|² + k1² |(Fn^T y2)_01|²).
bool RefineFundamental(const Points2& x1, const Points2& x2, Eigen::Matrix3d* F) {
  const size_t n = x1.size();
  if (n < 9 || n != x2.size()) return false;
  const Eigen::Matrix3d T1 = NormalisingTransform(x1), T2 = NormalisingTransform(x2);
  const double k1 = T1(0, 0), k2 = T2(0, 0);
  std::vector<Eigen::Vector3d> y1(n), y2(n);
  for (size_t i = 0; i < n; ++i) {
    y1[i] = T1 * x1[i].homogeneous();
    y2[i] = T2 * x2[i].homogeneous();
  }
  Eigen::Matrix3d Fn = T2.transpose().inverse() * (*F) * T1.inverse();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(Fn, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  if (U.determinant() < 0) U = -U;  // F's overall sign is irrelevant: flip both to stay in SO(3)
  if (V.determinant() < 0) V = -V;
  const Eigen::Vector3d& sv = svd.singularValues();
  if (!(sv(0) > 0)) return false;
  double s = sv(1) / sv(0);

  auto make_F = [](const Eigen::Matrix3d& U, const Eigen::Matrix3d& V, double s) -> Eigen::Matrix3d {
    return U.col(0) * V.col(0).transpose() + s * U.col(1) * V.col(1).transpose();
  };
  auto cost = [&](const Eigen::Matrix3d& M) {
    double c = 0;
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d g = M * y1[i], h = M.transpose() * y2[i];
      const double d = k2 * k2 * g.head<2>().squaredNorm() + k1 * k1 * h.head<2>().squaredNorm();
      const double a = y2[i].dot(g);
      c += a * a / std::max(d, 1e-300);
    }
    return c;
  };
  auto exp_so3 = [](const Eigen::Vector3d& w) -> Eigen::Matrix3d {
    const double th = w.norm();
    if (th < 1e-12) return Eigen::Matrix3d::Identity();
    return Eigen::AngleAxisd(th, w / th).toRotationMatrix();
  };
  const double initial_cost = cost(make_F(U, V, s));
  double current = initial_cost, lambda = 1e-3;
  for (int iter = 0; iter < 30; ++iter) {
    Fn = make_F(U, V, s);
    // dFn/dp for p = (wu, wv, s): columns of a 9x7 matrix (Fn row-major flattened).
    Eigen::Matrix<double, 9, 7> dF;
    const Eigen::Matrix3d Dm = Eigen::Vector3d(1, s, 0).asDiagonal();
    for (int k = 0; k < 3; ++k) {
      Eigen::Matrix3d ek = Eigen::Matrix3d::Zero();
      const Eigen::Vector3d e = Eigen::Vector3d::Unit(k);
      ek << 0, -e.z(), e.y(), e.z(), 0, -e.x(), -e.y(), e.x(), 0;
      const Eigen::Matrix3d dU = U * ek * Dm * V.transpose();
      const Eigen::Matrix3d dV = -U * Dm * ek * V.transpose();  // (V exp(w))^T = exp(-w) V^T
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
          dF(3 * r + c, k) = dU(r, c);
          dF(3 * r + c, 3 + k) = dV(r, c);
        }
    }
    const Eigen::Matrix3d dS = U.col(1) * V.col(1).transpose();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) dF(3 * r + c, 6) = dS(r, c);

    Eigen::Matrix<double, 7, 7> JtJ = Eigen::Matrix<double, 7, 7>::Zero();
    Eigen::Matrix<double, 7, 1> Jtr = Eigen::Matrix<double, 7, 1>::Zero();
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d g = Fn * y1[i], h = Fn.transpose() * y2[i];
      const double d = std::max(k2 * k2 * g.head<2>().squaredNorm() + k1 * k1 * h.head<2>().squaredNorm(), 1e-300);
      const double a = y2[i].dot(g), sd = std::sqrt(d);
      const double r = a / sd;
      // dr/dFn(p, q) = y2_p y1_q / sd - a / (2 d sd) * dd/dFn(p, q)
      Eigen::Matrix<double, 1, 9> drdF;
      for (int pp = 0; pp < 3; ++pp)
        for (int q = 0; q < 3; ++q) {
          double dd = 0;
          if (pp < 2) dd += 2 * k2 * k2 * g(pp) * y1[i](q);
          if (q < 2) dd += 2 * k1 * k1 * h(q) * y2[i](pp);
          drdF(3 * pp + q) = y2[i](pp) * y1[i](q) / sd - a / (2 * d * sd) * dd;
        }
      const Eigen::Matrix<double, 1, 7> J = drdF * dF;
      JtJ.noalias() += J.transpose() * J;
      Jtr.noalias() += J.transpose() * r;
    }
    bool improved = false;
    for (int attempt = 0; attempt < 10 && !improved; ++attempt) {
      Eigen::Matrix<double, 7, 7> A = JtJ;
      A.diagonal() += lambda * JtJ.diagonal().cwiseMax(1e-12);
      const Eigen::Matrix<double, 7, 1> step = -A.ldlt().solve(Jtr);
      if (!step.allFinite()) return false;
      const Eigen::Matrix3d U2 = U * exp_so3(step.head<3>()), V2 = V * exp_so3(step.segment<3>(3));
      const double s2 = s + step(6);
      const double c2 = cost(make_F(U2, V2, s2));
      if (c2 < current) {
        const double rel = (current - c2) / std::max(current, 1e-300);
        U = U2;
        V = V2;
        s = s2;
        current = c2;
        lambda = std::max(lambda / 10, 1e-12);
        improved = true;
        if (rel < 1e-10) iter = 1000;  // converged
      } else {
        lambda *= 10;
      }
    }
    if (!improved) break;
  }
  if (!(current <= initial_cost)) return false;
  const Eigen::Matrix3d Fr = T2.transpose() * make_F(U, V, s) * T1;
  if (!Fr.allFinite() || !(Fr.norm() > 0)) return false;
  *F = Fr / Fr.norm();
  return true;
}

bool RefineRelativePose(const Points2& n1, const Points2& n2, double focal, Eigen::Matrix3d* R, Eigen::Vector3d* t) {
  if (n1.size() < 6 || n1.size() != n2.size() || !(t->norm() > 0)) return false;
  Eigen::Quaterniond q(*R);
  double pq[4] = {q.x(), q.y(), q.z(), q.w()};
  Eigen::Vector3d tn = t->normalized();
  double pt[3] = {tn.x(), tn.y(), tn.z()};
  ceres::Problem problem;
  for (size_t i = 0; i < n1.size(); ++i) {
    auto* cost = new ceres::AutoDiffCostFunction<SampsonECost, 1, 4, 3>(new SampsonECost{n1[i], n2[i], focal});
    // Soft outlier down-weighting: the inliers come from a threshold of a few pixels.
    problem.AddResidualBlock(cost, new ceres::CauchyLoss(2.0), pq, pt);
  }
  problem.SetManifold(pq, new ceres::EigenQuaternionManifold);
  problem.SetManifold(pt, new ceres::SphereManifold<3>);
  ceres::Solver::Summary summary;
  ceres::Solve(SmallSolverOptions(), &problem, &summary);
  if (!summary.IsSolutionUsable() || summary.final_cost > summary.initial_cost) return false;
  *R = Eigen::Quaterniond(pq[3], pq[0], pq[1], pq[2]).normalized().toRotationMatrix();
  *t = Eigen::Vector3d(pt[0], pt[1], pt[2]).normalized();
  return true;
}

void TwoViewOptions::Check() const {
  if (max_error_px < 0) throw Error("two-view: max error must be >= 0 (0 = auto)");
  if (!(confidence > 0 && confidence < 1)) throw Error("two-view: confidence must be in (0, 1)");
  if (max_iterations < 1) throw Error("two-view: max iterations must be >= 1");
  if (min_inliers < 8) throw Error("two-view: min inliers must be >= 8");
  if (!(min_E_F_inlier_ratio > 0 && min_E_F_inlier_ratio <= 1))
    throw Error("two-view: min E/F inlier ratio must be in (0, 1]");
  if (!(max_H_inlier_ratio > 0 && max_H_inlier_ratio <= 1))
    throw Error("two-view: max H/F inlier ratio must be in (0, 1]");
}

double RotationAngle(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb) {
  // ||Ra - Rb||_F = 2 sqrt(2) sin(θ/2): accurate for small angles, where acos((trace - 1) / 2) is not.
  const double x = std::min(1.0, (Ra - Rb).norm() / (2 * std::sqrt(2.0)));
  return 2 * std::asin(x);
}

namespace {

// F: 8-point in USAC (OpenCV), then our normalised 8-point on all inliers + Sampson refinement. Sets F and its
// inliers (over all correspondences) when USAC finds a model.
void FitTwoViewF(const Points2& x1, const Points2& x2, const std::vector<cv::Point2d>& p1,
                 const std::vector<cv::Point2d>& p2, double thr, const TwoViewOptions& options, TwoViewResult* res) {
  const size_t n = x1.size();
  const double thr_sq = thr * thr;
  cv::Mat mask;
  cv::Mat Fcv;
  try {
    Fcv = cv::findFundamentalMat(p1, p2, cv::USAC_FM_8PTS, thr, options.confidence, options.max_iterations, mask);
  } catch (const cv::Exception&) {
    Fcv.release();
  }
  if (Fcv.rows != 3 || Fcv.cols != 3) return;
  Eigen::Matrix3d F;
  cv::cv2eigen(Fcv, F);
  std::vector<char> m(n, 0);
  for (size_t i = 0; i < n; ++i) m[i] = mask.at<uchar>(static_cast<int>(i)) != 0;
  Points2 y1, y2;
  // Two rounds: fit on the inliers, re-select with the refined model.
  for (int round = 0; round < 2; ++round) {
    Select(x1, x2, m, &y1, &y2);
    Eigen::Matrix3d F8;
    if (!EightPointFundamental(y1, y2, &F8)) break;
    if (options.refine) RefineFundamental(y1, y2, &F8);
    std::vector<char> m2;
    const int count = CountInliers(F8, x1, x2, thr_sq, 1.0, &m2);
    if (count < std::count(m.begin(), m.end(), 1) * 0.9 && round == 0) break;  // refit made it worse
    F = F8;
    m = m2;
  }
  res->F = F / F.norm();
  res->num_inliers_F = CountInliers(res->F, x1, x2, thr_sq, 1.0, &res->inliers_F);
}

// H (planar scene or pure rotation test), estimated on s1, s2; its inliers counted over all correspondences.
void FitTwoViewH(const Points2& x1, const Points2& x2, const std::vector<cv::Point2d>& s1,
                 const std::vector<cv::Point2d>& s2, double thr, const TwoViewOptions& options, TwoViewResult* res) {
  const size_t n = x1.size();
  cv::Mat mask;
  cv::Mat Hcv = cv::findHomography(s1, s2, cv::RANSAC, thr, mask, options.max_iterations, options.confidence);
  if (Hcv.rows != 3 || Hcv.cols != 3) return;
  cv::cv2eigen(Hcv, res->H);
  res->inliers_H.assign(n, 0);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d h = res->H * x1[i].homogeneous();
    if (h.z() != 0 && (h.hnormalized() - x2[i]).squaredNorm() <= thr * thr) {
      res->inliers_H[i] = 1;
      ++res->num_inliers_H;
    }
  }
}

// Triangulation angles (radians) of the E-inliers whose rays meet in front of both cameras: rays d1 (cam-1
// frame) and R^T n2 from C2 = -R^T t.
std::vector<double> AnglesInFront(const Points2& n1, const Points2& n2, const std::vector<char>& inliers,
                                  const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  std::vector<double> angles;
  const Eigen::Vector3d C2 = -R.transpose() * t;
  for (size_t i = 0; i < n1.size(); ++i) {
    if (!inliers[i]) continue;
    const Eigen::Vector3d d1 = n1[i].homogeneous().normalized();
    const Eigen::Vector3d d2 = (R.transpose() * n2[i].homogeneous()).normalized();
    // Closest points of the two rays: X = λ1 d1 = C2 + λ2 d2.
    Eigen::Matrix<double, 3, 2> A;
    A << d1, -d2;
    const Eigen::Vector2d lam = (A.transpose() * A).ldlt().solve(A.transpose() * C2);
    if (lam(0) > 0 && lam(1) > 0) angles.push_back(std::acos(std::clamp(d1.dot(d2), -1.0, 1.0)));
  }
  return angles;
}

// E with the (prior) intrinsics: 5-point in RANSAC on F's inliers in normalised coordinates, pose refinement;
// the pose is kept when most E-inliers triangulate in front of both cameras.
void FitTwoViewE(const Points2& x1, const Points2& x2, const core::Camera& camera1, const core::Camera& camera2,
                 double thr, const TwoViewOptions& options, TwoViewResult* res) {
  const size_t n = x1.size();
  const double focal = 0.5 * (camera1.fx() + camera1.fy() + camera2.fx() + camera2.fy()) / 2;
  Points2 n1(n), n2(n);
  for (size_t i = 0; i < n; ++i) {
    n1[i] = camera1.Unproject(x1[i]).hnormalized();
    n2[i] = camera2.Unproject(x2[i]).hnormalized();
  }
  std::vector<cv::Point2d> c1, c2;
  for (size_t i = 0; i < n; ++i)
    if (res->inliers_F[i]) {
      c1.emplace_back(n1[i].x(), n1[i].y());
      c2.emplace_back(n2[i].x(), n2[i].y());
    }
  cv::Mat mask;
  cv::Mat Ecv;
  try {
    Ecv = cv::findEssentialMat(c1, c2, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC, options.confidence, thr / focal,
                               options.max_iterations, mask);
  } catch (const cv::Exception&) {
    Ecv.release();
  }
  if (Ecv.rows != 3 || Ecv.cols != 3 || cv::countNonZero(mask) < 6) return;
  cv::Mat Rcv, tcv, pose_mask = mask.clone();
  const int in_front = cv::recoverPose(Ecv, c1, c2, cv::Mat::eye(3, 3, CV_64F), Rcv, tcv, pose_mask);
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  cv::cv2eigen(Rcv, R);
  cv::cv2eigen(tcv, t);
  if (options.refine && in_front > 0) {
    Points2 y1, y2;
    for (int i = 0; i < mask.rows; ++i)
      if (mask.at<uchar>(i)) {
        y1.emplace_back(c1[i].x, c1[i].y);
        y2.emplace_back(c2[i].x, c2[i].y);
      }
    RefineRelativePose(y1, y2, focal, &R, &t);
  }
  res->E = Skew(t) * R;
  res->num_inliers_E = CountInliers(res->E, n1, n2, thr * thr, focal * focal, &res->inliers_E);
  std::vector<double> angles = AnglesInFront(n1, n2, res->inliers_E, R, t);
  if (angles.size() * 2 >= static_cast<size_t>(res->num_inliers_E) && res->num_inliers_E >= options.min_inliers) {
    res->has_pose = true;
    res->R = R;
    res->t = t;
    res->median_triangulation_angle_deg = core::Median(std::move(angles)) * 180.0 / M_PI;
  }
}

// The pair's class from the three models' inlier counts, and the inliers of the chosen model: E's when the
// intrinsics are trusted and E explains the data, else F's (which do not depend on the intrinsics); H's when F
// failed (pure rotation may starve F).
void ClassifyTwoView(bool trust_intrinsics, const TwoViewOptions& options, TwoViewResult* res) {
  const int nF = res->num_inliers_F, nE = res->num_inliers_E, nH = res->num_inliers_H;
  if (std::max(nF, nH) < options.min_inliers) return;  // rejected
  const bool e_consistent = nE >= options.min_E_F_inlier_ratio * nF && nE >= options.min_inliers;
  if (nF < options.min_inliers || nH > options.max_H_inlier_ratio * nF) {
    res->geometry = TwoViewClass::kPlanarOrRotation;
  } else {
    res->geometry = e_consistent ? TwoViewClass::kCalibrated : TwoViewClass::kUncalibrated;
  }
  const std::vector<char>* chosen = &res->inliers_F;
  if (trust_intrinsics && e_consistent) chosen = &res->inliers_E;
  if (nF < options.min_inliers) chosen = &res->inliers_H;
  for (size_t i = 0; i < chosen->size(); ++i)
    if ((*chosen)[i]) res->inliers.push_back(static_cast<int>(i));
}

}  // namespace

TwoViewResult VerifyTwoView(const Points2& x1, const Points2& x2, const core::Camera& camera1,
                            const core::Camera& camera2, bool trust_intrinsics, const TwoViewOptions& options) {
  TwoViewResult res;
  const size_t n = x1.size();
  if (n != x2.size()) throw Error("two-view: correspondence lists differ in length");
  if (n < static_cast<size_t>(std::max(options.min_inliers, 8))) return res;
  const double thr =
      options.max_error_px > 0
          ? options.max_error_px
          : std::max(1.5, std::max({camera1.width, camera1.height, camera2.width, camera2.height}) / 2000.0);
  const auto p1 = ToCv(x1), p2 = ToCv(x2);
  // OpenCV's RANSAC and USAC draw from fixed-seed generators: deterministic. (options.seed is kept for our own
  // sampling; OpenCV 4.6 exposes no seed through these entry points.)
  FitTwoViewF(x1, x2, p1, p2, thr, options, &res);

  // RANSAC for H and E on F's inliers when F found enough: their inliers lie (almost) within F's, and a sample
  // set with few outliers ends RANSAC after tens of iterations instead of thousands. Inliers are then counted
  // over all correspondences. When F failed (pure rotation can starve it), H searches everything.
  const bool f_ok = res.num_inliers_F >= options.min_inliers;
  std::vector<cv::Point2d> f1, f2;
  if (f_ok)
    for (size_t i = 0; i < n; ++i)
      if (res.inliers_F[i]) {
        f1.push_back(p1[i]);
        f2.push_back(p2[i]);
      }
  FitTwoViewH(x1, x2, f_ok ? f1 : p1, f_ok ? f2 : p2, thr, options, &res);
  // E only for pairs F supports: the 5-point RANSAC is the costly part on hopeless pairs.
  if (f_ok) FitTwoViewE(x1, x2, camera1, camera2, thr, options, &res);
  ClassifyTwoView(trust_intrinsics, options, &res);
  return res;
}

}  // namespace fmv3d::geometry
