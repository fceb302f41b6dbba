#include "fmv3d/sfm/focal_scan.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <tuple>
#include <utility>
#include <vector>

namespace fmv3d::sfm {

namespace {

// Mean truncated squared Sampson error (px²) of E over normalised points; f and each match's scale (undistorted
// to image pixels) convert to pixels.
double MsacScore(const Eigen::Matrix3d& E, const std::vector<cv::Point2d>& p1, const std::vector<cv::Point2d>& p2,
                 const std::vector<double>& scale, double f, double threshold_px) {
  const double t2 = threshold_px * threshold_px;
  double sum = 0;
  for (size_t i = 0; i < p1.size(); ++i) {
    const Eigen::Vector3d a(p1[i].x, p1[i].y, 1), b(p2[i].x, p2[i].y, 1);
    const Eigen::Vector3d Ea = E * a, Etb = E.transpose() * b;
    const double num = b.dot(Ea);
    const double den = Ea.head<2>().squaredNorm() + Etb.head<2>().squaredNorm();
    const double e2 = den > 0 ? f * f * scale[i] * scale[i] * num * num / den : t2;
    sum += std::min(e2, t2);
  }
  return sum / std::max<size_t>(1, p1.size());
}

// Median of each value and its two neighbours (at the ends, of the first or last three).
std::vector<double> MedianOfNeighbours(const std::vector<double>& v) {
  if (v.size() < 3) return v;
  std::vector<double> m(v.size());
  for (size_t i = 0; i < v.size(); ++i) {
    const size_t c = std::clamp<size_t>(i, 1, v.size() - 2);
    const double a = v[c - 1], b = v[c], d = v[c + 1];
    m[i] = std::max(std::min(a, b), std::min(std::max(a, b), d));
  }
  return m;
}

// Undistorted pixel of p under the division model κ about the principal point (ρ over the half-diagonal R), and
// the local scale of that map (geometric mean of its radial and tangential gains) to bring errors back to pixels
// of the image.
Eigen::Vector2d UndistortDivision(const core::Camera& cam, double kappa, double inv_r2, const Eigen::Vector2d& p,
                                  double* gain) {
  const Eigen::Vector2d d(p.x() - cam.u0, p.y() - cam.v0);
  const double k = kappa * d.squaredNorm() * inv_r2;
  *gain = std::sqrt(std::max(1e-6, 1 - k) / std::pow(std::max(1e-3, 1 + k), 3));
  return Eigen::Vector2d(cam.u0, cam.v0) + d / std::max(1e-3, 1 + k);
}

// Score of one lens (focal f, division κ) on every pair: the best essential matrix's mean truncated squared
// Sampson error in image pixels, summed over pairs.
double ScoreLens(const core::Camera& camera, double f, double kappa, const std::vector<FocalScanPair>& pairs,
                 const FocalScanOptions& o) {
  core::Camera cam = camera;
  cam.f = f;
  const double half_diag = 0.5 * std::hypot(cam.width, cam.height);
  const double inv_r2 = half_diag > 0 ? 1 / (half_diag * half_diag) : 0;
  const cv::Matx33d K(cam.fx(), 0, cam.u0, 0, cam.fy(), cam.v0, 0, 0, 1);
  std::vector<cv::Point2d> p1, p2, q1, q2;
  std::vector<double> scale;
  double total = 0;
  for (const auto& pr : pairs) {
    if (pr.uv1.size() < 8 || pr.uv1.size() != pr.uv2.size()) continue;
    p1.clear();
    p2.clear();
    q1.clear();
    q2.clear();
    scale.clear();
    for (size_t i = 0; i < pr.uv1.size(); ++i) {
      double g1 = 1, g2 = 1;
      const Eigen::Vector2d u1 = kappa != 0 ? UndistortDivision(cam, kappa, inv_r2, pr.uv1[i], &g1) : pr.uv1[i];
      const Eigen::Vector2d u2 = kappa != 0 ? UndistortDivision(cam, kappa, inv_r2, pr.uv2[i], &g2) : pr.uv2[i];
      const Eigen::Vector2d a = cam.Unproject(u1).head<2>();  // z = 1
      const Eigen::Vector2d b = cam.Unproject(u2).head<2>();
      p1.emplace_back(a.x(), a.y());
      p2.emplace_back(b.x(), b.y());
      // Undistorted pixels for the estimator, so its threshold is in pixels at every candidate focal.
      q1.emplace_back(cam.fx() * a.x() + cam.u0, cam.fy() * a.y() + cam.v0);
      q2.emplace_back(cam.fx() * b.x() + cam.u0, cam.fy() * b.y() + cam.v0);
      scale.push_back(2 / (g1 + g2));
    }
    double best = o.threshold_px * o.threshold_px;  // no model: every match counts as an outlier
    // USAC with MSAC scoring and local optimisation: plain RANSAC's luck shows up as score noise between
    // neighbouring candidates, larger than the differences the scan looks for.
    cv::UsacParams up;
    up.confidence = 0.999;
    up.maxIterations = o.ransac_iterations;
    up.threshold = o.threshold_px;
    up.loMethod = cv::LOCAL_OPTIM_INNER_LO;
    up.score = cv::SCORE_METHOD_MSAC;
    up.sampler = cv::SAMPLING_UNIFORM;
    up.randomGeneratorState = static_cast<int>(o.seed);
    up.isParallel = false;
    cv::Mat E, mask;
    try {
      E = cv::findEssentialMat(q1, q2, K, K, cv::noArray(), cv::noArray(), mask, up);
    } catch (const cv::Exception&) {
      E = cv::Mat();
    }
    // Several solutions may come stacked (3k x 3): the best of them scores the candidate.
    for (int s = 0; s + 3 <= E.rows && E.cols == 3; s += 3) {
      Eigen::Matrix3d Ee;
      cv::cv2eigen(E.rowRange(s, s + 3), Ee);
      best = std::min(best, MsacScore(Ee, p1, p2, scale, f, o.threshold_px));
    }
    total += best;
  }
  return total;
}

int NumUsablePairs(const std::vector<FocalScanPair>& pairs) {
  return static_cast<int>(std::count_if(pairs.begin(), pairs.end(), [](const FocalScanPair& p) {
    return p.uv1.size() >= 8 && p.uv1.size() == p.uv2.size();
  }));
}

// Does the division model explain the pairs clearly better than any pinhole focal, with a lens that bends the image
// like an action camera's? Two conditions. Its best score is at most distortion_gain of the pinhole's; and its κ
// moves the corner by at least min_kappa of its radius. The score ratio alone reads the noise floor and the pairs'
// baselines as much as the lens: a mild lens (k1 −0.08 on 960x540, E2eSparse's) scored 0.82 there and 0.84 on
// synthetic orbit pairs, at the edge of 0.8; so does the error the division model removes (2.7e-4 and 5.3e-4 of the
// half-diagonal, rms per pair, against 8e-4…1.1e-3 on action-camera clips). The best κ does not: −0.05 (the mildest
// candidate) on both mild flights, −0.30…−0.50 on the action-camera clips (k1 −0.27…−0.30 on 854x480), a factor of two
// or more on each side of the bound. A mild lens left to the pinhole decision is refined by bundle adjustment as
// before.
bool DistortionExplains(const core::Camera& camera, int num_pairs, double kappa, const FocalScanOptions& o,
                        FocalScanResult* r) {
  const double half_diagonal = 0.5 * std::hypot(camera.width, camera.height);
  const double excess = r->pinhole_best - r->division_best;
  r->division_excess = excess > 0 && num_pairs > 0 ? std::sqrt(excess / num_pairs) / half_diagonal : 0;
  return r->division_best <= o.distortion_gain * r->pinhole_best && std::abs(kappa) >= o.min_kappa - 1e-9;
}

}  // namespace

void DecidePinhole(const FocalScanOptions& o, FocalScanResult* out) {
  FocalScanResult& r = *out;
  if (r.scores.empty()) return;
  // Flat: every candidate explains the matches about equally well (optical axes that meet, as in an orbit around its
  // target, or near-affine views), and the best is one candidate's luck (a lucky or failed minimal sample; at very
  // long focals the five-point solver degenerates). Two views bound nothing: the shortest candidate is the lower
  // bound, and the multi-view dolly-zoom scan decides from there. The flatness test reads the median of each
  // candidate and its neighbours, so one such jump does not decide it.
  const std::vector<double> smooth = MedianOfNeighbours(r.scores);
  const auto [lo, hi] = std::minmax_element(smooth.begin(), smooth.end());
  auto undetermined = [&r] {
    r.undetermined = r.plateau = true;
    r.focal = r.focals.front();
  };
  if (*hi <= (1 + o.flat_tolerance) * *lo) return undetermined();
  // The smoothing below erases a minimum at the shortest candidate (its median takes the two candidates after it).
  // The widest field is where the five-point solver is best conditioned, so a shortest candidate that beats every
  // other by more than the tolerance is a minimum there: a start that bundle adjustment refines, not a bound to hold
  // (a 24-frame 960x540 orbit: 0.480 px² at 576 px, every longer candidate ≥ 0.611; truth 831; held at 576 through
  // growth it ended 0.39% off, refined from it 0.007%).
  const double rest = *std::min_element(r.scores.begin() + 1, r.scores.end());
  if (r.scores.front() * (1 + o.tolerance) < rest) {
    r.focal = r.focals.front();
    r.plateau = false;
    return;
  }
  // A plateau holds the focal as a lower bound through growth, and the dolly-zoom scan only lengthens it: it must be
  // a level and a knee the curve supports. Both are read on the smoothed curve (a level held by several neighbouring
  // candidates, not by lucky minimal samples at the long end), and the candidates short of the knee must score
  // clearly worse than that level (knee_contrast): a focal far too short leaves the five-point solver's residuals
  // near their truncation, while a curve that only drifts down by tens of percent under noise of ±10–20% between
  // neighbours (orbit pairs) has no knee. Without one, it is the flat case.
  const double level = *lo, smooth_limit = (1 + o.tolerance) * level + 1e-12;
  if (smooth.back() <= smooth_limit) {
    if (smooth.front() < o.knee_contrast * level) return undetermined();
    size_t knee = 0;
    while (knee + 1 < smooth.size() && smooth[knee] > smooth_limit) ++knee;
    r.focal = r.focals[knee];
    r.plateau = true;
    return;
  }
  // A minimum: a start for bundle adjustment, which refines it. Its valley is where the smoothed curve is lowest:
  // one candidate's lucky sample far from it is no minimum (an oblique sideways pass, recorded: 0.733 px² at 6.35x
  // the guess between neighbours of 1.06 and 0.99, against a valley of 0.785–0.812 around the true focal; started
  // there, bundle adjustment ran off to 35x the true focal). The best raw score of the valley sets the limit.
  const size_t valley = static_cast<size_t>(lo - smooth.begin());
  const size_t v0 = valley == 0 ? 0 : valley - 1, v1 = std::min(valley + 1, r.scores.size() - 1);
  const double best = *std::min_element(r.scores.begin() + static_cast<std::ptrdiff_t>(v0),
                                        r.scores.begin() + static_cast<std::ptrdiff_t>(v1) + 1);
  const double limit = (1 + o.tolerance) * best + 1e-12;
  size_t chosen = 0;
  while (chosen + 1 < r.scores.size() && r.scores[chosen] > limit) ++chosen;
  r.focal = r.focals[chosen];
  r.plateau = false;
}

namespace {

// Barrel distortion at the wide end of the pinhole range (guess · min_factor: a field of view of ~80° for the usual
// 1.2·width guess), κ in steps of 0.05; pincushion (κ > 0, a lens that stretches its corners, rarer and milder) at the
// pinhole scan's own choice, where such a lens's focal is. Returns true (and sets the decision in *r) when the
// division model explains the matches clearly better than the pinhole scan's best (DistortionExplains). Measured on
// oblique action-camera clips (forward flight over near-planar ground, k1 −0.27…−0.30): a joint (f, κ) grid lowers the
// score by a third or more at every focal from 0.25x to 2x the guess, but its minimum over f is noise (κ and f trade; a
// one-parameter model does not fit such a lens to better than a few pixels) and started bundle adjustment at 3.5x the
// true focal, where it diverged. Two views show that the lens distorts; the views together decide its focal
// (ScanFocal's header).
bool ScanDivision(const core::Camera& camera, const std::vector<FocalScanPair>& pairs, const FocalScanOptions& o,
                  FocalScanResult* r) {
  std::array<double, 3> best = {0, 0, std::numeric_limits<double>::infinity()};
  auto score = [&](double f, double kappa) {
    const double s = ScoreLens(camera, f, kappa, pairs, o);
    r->division_cells.push_back({f, kappa, s});
    if (s < best[2]) best = {f, kappa, s};
  };
  const double wide = camera.f * o.min_factor;
  for (double kappa = -o.division_step; kappa >= o.min_division - 1e-9; kappa -= o.division_step) score(wide, kappa);
  for (double kappa = o.division_step; kappa <= o.max_division + 1e-9; kappa += o.division_step) score(r->focal, kappa);
  r->division_best = best[2];
  if (!DistortionExplains(camera, NumUsablePairs(pairs), best[1], o, r)) return false;
  // A pincushion lens keeps the pinhole decision's focal and its kind (a plateau stays a lower bound); a barrel
  // lens starts at the wide end, neither a plateau nor a bound (the header says why).
  if (best[1] < 0) r->plateau = r->undetermined = false;
  r->focal = best[0];
  r->division = best[1];
  std::tie(r->k1, r->k2) = DivisionToBrown(best[1], best[0], 0.5 * std::hypot(camera.width, camera.height));
  return true;
}

}  // namespace

std::pair<double, double> DivisionToBrown(double kappa, double f, double half_diagonal) {
  // r_d/r_u − 1 = k1 r_u² + k2 r_u⁴ over distorted radii up to the corner (normalised: pixels / f).
  Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  for (int i = 1; i <= 50; ++i) {
    const double rho = i / 50.0, rd = rho * half_diagonal / f;
    const double ru = rd / (1 + kappa * rho * rho);
    const Eigen::Vector2d a(ru * ru, ru * ru * ru * ru);
    A += a * a.transpose();
    b += a * (rd / ru - 1);
  }
  const Eigen::Vector2d k = A.ldlt().solve(b);
  return {k(0), k(1)};
}

FocalScanResult ScanFocal(const core::Camera& camera, const std::vector<FocalScanPair>& pairs,
                          const FocalScanOptions& o) {
  FocalScanResult r;
  r.focal = camera.f;
  if (NumUsablePairs(pairs) == 0) return r;
  for (double k = o.min_factor; k <= o.max_factor * 1.0001; k *= o.step) r.focals.push_back(camera.f * k);
  r.scores.resize(r.focals.size());
  for (size_t c = 0; c < r.focals.size(); ++c) r.scores[c] = ScoreLens(camera, r.focals[c], 0, pairs, o);
  r.pinhole_best = *std::min_element(r.scores.begin(), r.scores.end());
  DecidePinhole(o, &r);
  if (o.scan_distortion && !camera.HasDistortion()) {
    const auto start = std::chrono::steady_clock::now();
    ScanDivision(camera, pairs, o, &r);
    r.division_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return r;
}

}  // namespace fmv3d::sfm
