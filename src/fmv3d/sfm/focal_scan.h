// Focal length from two-view geometry when the prior is only a guess.
//
// Why a scan and not self-calibration from F: with a long lens (telephoto video, a field of view of a few
// degrees or less) every view is close to affine, and the Kruppa / Bougnoux focal from F is undefined or
// wildly unstable. What still holds: an essential matrix built with a focal that is far too short cannot
// explain the near-affine motion, its epipolar residuals grow; any focal at or beyond the true one explains
// the matches about equally well (the affine limit). So we score each candidate focal by how well the best
// essential matrix explains every pair's matches (truncated squared Sampson error in pixels, MSAC-like), and
// keep the shortest focal whose score is within a tolerance of the best — the knee of the curve. For ordinary
// lenses the curve has a clear minimum near the true focal; for telephoto it is a plateau, and the knee is a
// lower bound of the order of the true focal (the remaining ambiguity is the affine one: focal and depth trade).
// A curve flat over the whole range determines nothing (the optical axes of an orbit around its target meet, which
// makes the two-view focal undefined; near-affine views explain as well at any focal): its shortest candidate is
// the lower bound, and the multi-view dolly-zoom scan (dolly_zoom_scan.h) decides from there. So is a curve whose
// "plateau" is not supported: its level is read on the median of neighbouring candidates (lucky minimal samples at
// the long end do not make one), and the shortest candidates must score knee_contrast times worse than it
// (DecidePinhole). Measured: with each
// candidate's pose refined to its optimum rather than taken from a minimal sample, telephoto curves are flat too;
// a knee comes from how the five-point solver fails at focals far too short, so it is only a lower bound.
//
// Wide lenses (action cameras, k1 ≈ −0.3): tens of pixels of barrel distortion at the corners, which no pinhole
// essential matrix explains at any focal (the pinhole curve falls monotonically, near its truncation everywhere,
// and reads as a telephoto plateau). So the scan also tries a one-parameter division model (Fitzgibbon's:
// undistorted = distorted / (1 + κ ρ²), ρ the radius over the half-diagonal, so κ means the same at every focal)
// at the wide end of its range. When that explains the matches clearly better than any pinhole focal
// (distortion_gain), the lens is wide and distorting: two views do not decide its focal (with distortion free,
// focal and κ trade over a wide range), so the result is a start — the wide end, with the κ found as k1, k2 —
// and neither a plateau nor a bound: bundle adjustment refines focal and distortion from the first views on, and
// the views together determine them. On a lens without measurable distortion the extra parameter buys nothing,
// and a mild one (best |κ| below min_kappa: it moves the corner by less than 15%) is refined by bundle adjustment from
// the pinhole decision as before (DistortionExplains in the source says why the κ and not the score ratio decides).
// Pincushion (κ > 0) is scored at the pinhole decision's focal and, found, only adds its k1, k2 to that decision.
#pragma once

#include <Eigen/Core>
#include <array>
#include <utility>
#include <vector>

#include "fmv3d/core/camera.h"

namespace fmv3d::sfm {

struct FocalScanPair {
  std::vector<Eigen::Vector2d> uv1, uv2;  // matched keypoints (pixels) of one pair, same camera model
};

struct FocalScanOptions {
  double min_factor = 0.5, max_factor = 128;  // candidates: guess · factor, geometric steps
  double step = 1.26;                         // ratio between consecutive candidates (2^(1/3))
  double threshold_px = 2.0;                  // MSAC truncation and RANSAC inlier threshold
  double tolerance = 0.05;                    // knee: first candidate with score ≤ (1 + tolerance) · best
  double flat_tolerance = 0.15;               // undetermined: every candidate within (1 + this) · best
  double knee_contrast = 2;                   // plateau: the shortest candidate scores ≥ this · the plateau's level
  int ransac_iterations = 1000;
  uint64_t seed = 1;
  // The division scan for barrel and pincushion distortion; skipped when the prior states a distortion.
  bool scan_distortion = true;
  double min_division = -0.5;    // most negative κ (the corner's undistorted radius 1/(1 + κ) = 2)
  double max_division = 0.3;     // most positive κ (pincushion)
  double division_step = 0.05;   // κ candidates: ±step, ±2·step, ... to min_division and max_division
  double distortion_gain = 0.8;  // accepted when its best score ≤ this · the pinhole's best
  double min_kappa = 0.15;       // ... and its |κ| at least this (DistortionExplains)
};

struct FocalScanResult {
  double focal = 0;            // chosen focal (pixels)
  bool plateau = false;        // the longest candidates score like the best: focal is only a lower bound
  bool undetermined = false;   // the curve is flat: focal is the shortest candidate, plateau is set
  std::vector<double> focals;  // candidates
  std::vector<double> scores;  // mean truncated squared Sampson error (px²), summed over pairs
  // The division scan: κ of the lens (0: pinhole, the scan above decided) and the same lens as Brown k1, k2 at the
  // chosen focal (a start for bundle adjustment); the best scores of both models; the candidates tried.
  double division = 0, k1 = 0, k2 = 0;
  double pinhole_best = 0, division_best = 0;
  double division_excess = 0;   // the error the division model removes: rms per pair / half-diagonal
  double division_seconds = 0;  // the division scan's share of the run time
  std::vector<std::array<double, 3>> division_cells;  // (focal, κ, score)
};

// Brown k1, k2 (core::Camera) of a division model κ (on ρ = pixel radius / half_diagonal) at focal f: the least
// squares fit over the image's radii.
std::pair<double, double> DivisionToBrown(double kappa, double f, double half_diagonal);

// The pinhole curve's decision from r->focals and r->scores (ascending focals): sets focal, plateau and
// undetermined — a minimum (a start for bundle adjustment), the knee of a plateau (a lower bound), or a flat curve.
void DecidePinhole(const FocalScanOptions& options, FocalScanResult* r);

// camera: the prior (principal point, distortion; its f is the guess the factors multiply).
// Deterministic for a fixed seed. Returns the guess (and empty scores) when no pair has ≥ 8 matches.
FocalScanResult ScanFocal(const core::Camera& camera, const std::vector<FocalScanPair>& pairs,
                          const FocalScanOptions& options = {});

}  // namespace fmv3d::sfm
