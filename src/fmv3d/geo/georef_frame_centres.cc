#include "fmv3d/geo/georef_frame_centres.h"

#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "fmv3d/core/stats.h"
#include "fmv3d/geo/accuracy.h"

namespace fmv3d::geo {
namespace {

// ST 0601 tags 25 (MSL) and 78 (HAE): 2 bytes over 19.9 km from −900 m, 0.30 m steps.
constexpr double kElevationStep = 19900.0 / 65535;

bool OnGrid(double h) {
  const double k = (h + 900) / kElevationStep;
  return std::abs(k - std::round(k)) < 1e-4;
}

// A frame centre's height in the fit's datum.
struct Height {
  double value = 0;
  bool coded = false;           // a 2-byte code: the truth is within ±step/2 of value
  std::optional<double> other;  // the other datum's code, moved into this one (when coded too)
  bool operator==(const Height& h) const {
    return std::abs(value - h.value) < 1e-6 && coded == h.coded && other.has_value() == h.other.has_value() &&
           (!other || std::abs(*other - *h.other) < 1e-6);
  }
};

// The geoid undulation from the packets that state both heights. A mean, not a median: both heights are 2-byte
// codes of one altitude, so their difference takes just two values around N (the median would pick one, up to
// half a step off); the GPS noise spreads the altitudes over many steps and the mean of the two values is N.
// (Trimmed to ±1 m of the median against outliers.) Returns (N, σ of the mean).
std::optional<std::pair<double, double>> Undulation(const std::vector<GeorefPair>& pairs) {
  std::vector<double> undulations;
  for (const auto& p : pairs)
    if (p.hae && p.msl) undulations.push_back(*p.hae - *p.msl);
  if (undulations.empty()) return std::nullopt;
  const double med = core::Median(undulations);
  double sum = 0, sq = 0;
  size_t n = 0;
  for (double u : undulations)
    if (std::abs(u - med) <= 1.0) sum += u, sq += u * u, ++n;
  const double mean = sum / static_cast<double>(n);
  return std::make_pair(mean, std::sqrt(std::max(0.0, sq / n - mean * mean) / static_cast<double>(n)));
}

// When a packet states both heights, the truth lies in both codes' intervals: the other datum's code, moved by
// the undulation, narrows the interval wherever the two grids do not line up — its edges blurred by the
// undulation estimate's σ.
std::optional<Height> FrameCentreHeight(const GeorefPair& p, bool hae, const std::optional<double>& undulation,
                                        double undulation_sigma, const LocalFrame& frame) {
  const auto& same = hae ? p.frame_centre_hae : p.frame_centre_msl;
  const auto& other = hae ? p.frame_centre_msl : p.frame_centre_hae;
  const std::optional<double> moved =
      other && undulation ? std::optional<double>(*other + (hae ? *undulation : -*undulation)) : std::nullopt;
  if (same) {
    Height h{*same, OnGrid(*same), std::nullopt};
    if (h.coded && moved && OnGrid(*other) && std::abs(*moved - *same) < kElevationStep + 5 * undulation_sigma)
      h.other = moved;
    return h;
  }
  if (moved) return Height{*moved, OnGrid(*other), std::nullopt};
  // No stated height: the point at the slant range (not a 2-byte code).
  if (const auto h = FrameCentreHeightFromRange(p, frame)) return Height{*h, false, std::nullopt};
  return std::nullopt;
}

// Prior of the offset u (truth − value) common to frame centres that all decode alike: uniform over the step,
// times the other code's step (blurred by the undulation's σ) when there is one. (u, weight) nodes.
std::vector<std::pair<double, double>> OffsetPrior(const Height& h, double undulation_sigma) {
  std::vector<std::pair<double, double>> nodes;
  const int n = 61;
  const double s_n = std::max(undulation_sigma, 1e-4);
  for (int k = 0; k < n; ++k) {
    const double u = kElevationStep * ((k + 0.5) / n - 0.5);
    double w = 1;
    if (h.other) {
      const double lo = *h.other - h.value - 0.5 * kElevationStep, hi = *h.other - h.value + 0.5 * kElevationStep;
      w = 0.5 * (std::erf((hi - u) / (std::sqrt(2.0) * s_n)) - std::erf((lo - u) / (std::sqrt(2.0) * s_n)));
    }
    nodes.emplace_back(u, w);
  }
  return nodes;
}

double PriorSd(const std::vector<std::pair<double, double>>& nodes) {
  double w = 0, m = 0, q = 0;
  for (const auto& [u, p] : nodes) w += p, m += p * u, q += p * u * u;
  return w > 0 ? std::sqrt(std::max(0.0, q / w - (m / w) * (m / w))) : 0.0;
}

}  // namespace

double GeorefFrameCentres::TranslationError() const {
  return used() ? std::sqrt(std::max(0.0, fusion->fused.covariance.bottomRightCorner<3, 3>().trace())) : 0.0;
}

nlohmann::json GeorefFrameCentres::ToJson() const {
  nlohmann::json j = {{"used", false}, {"observations", 0}};
  if (attempted && sights == 0) j["why"] = "no packet states a frame centre and a slant range";
  if (!fusion) return j;
  j.update(fusion->ToJson());
  j["elevation_steps"] = elevation_steps;
  j["elevation_encoding"] =
      encoding == ElevationEncoding::kExact
          ? "not on the 2-byte ST 0601 grid: no quantisation error"
          : std::string(encoding == ElevationEncoding::kOneCode ? "one 2-byte code for all: a common offset"
                                                                : "several 2-byte codes: a Gaussian floor") +
                (both_datums ? ", within the MSL and HAE codes' common interval" : ", within its step");
  j["elevation_offset_prior_sd_m"] = offset_prior_sd;
  if (undulation) {
    j["geoid_undulation_m"] = *undulation;
    j["geoid_undulation_sigma_m"] = undulation_sigma;
  }
  if (turn) {
    j["rotation_turn_deg"] = turn->deg;
    j["rotation_turn_chi2"] = turn->chi2;
    j["rotation_turn_applied"] = turn->applied;
  }
  return j;
}

GeorefFrameCentres FuseGeorefFrameCentres(const PositionFit& fit, const PairedTelemetry& paired,
                                          const AttitudeFusion& attitude, const LocalFrame& frame,
                                          double min_inlier_threshold) {
  GeorefFrameCentres out;
  out.attempted = true;
  out.sim = fit.sim;
  const std::vector<GeorefPair>& pairs = paired.fit();
  const bool hae = paired.datum == VerticalDatum::kEllipsoid;
  if (const auto u = Undulation(pairs)) out.undulation = u->first, out.undulation_sigma = u->second;
  const Eigen::Matrix3d R = fit.sim.q.toRotationMatrix();
  std::vector<Eigen::Vector3d> s_in, d_in, res(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) {
    res[i] = fit.sim.Apply(fit.src[i]) - fit.dst[i];
    if (fit.inliers[i]) s_in.push_back(fit.src[i]), d_in.push_back(fit.dst[i]);
  }
  // Only the keyframes' lines of sight: between keyframes the model's rotation is interpolated and misses the
  // gimbal's jitter, which the slant range turns into metres (0.4° at 700 m: 5 m, against 2 cm at keyframes).
  std::vector<LineOfSight> sights;
  std::vector<Height> heights;
  for (const GeorefPair& p : paired.keyframes) {
    const auto h = FrameCentreHeight(p, hae, out.undulation, out.undulation_sigma, frame);
    if (!p.frame_centre || !p.slant_range || !(*p.slant_range > 0) || !h) continue;
    heights.push_back(*h);
    sights.push_back({p.centre, p.rotation.conjugate() * Eigen::Vector3d::UnitZ(), *p.slant_range,
                      frame.ToEnu({p.frame_centre->lat, p.frame_centre->lon, h->value}), 0});
    out.by_name[p.name] = {sights.back().frame_centre, *p.slant_range};
  }
  out.sights = sights.size();
  const double rho_p = paired.use_track() ? ResidualAutocorrelation(pairs, res, fit.inliers) : 0.0;
  const double n_eff_p = std::max(1.0, s_in.size() * (1 - rho_p) / (1 + rho_p));
  // The positions' scale and translation under a rotation, with their covariance (σ², effective samples).
  const auto positions_under = [&](const Eigen::Matrix3d& rotation, ScaleShift* ss) {
    if (!geometry::EstimateScaleShift(rotation, s_in, d_in, std::vector<double>(s_in.size(), 1.0), ss)) return false;
    ss->covariance *= fit.sigma * fit.sigma * static_cast<double>(s_in.size()) / n_eff_p;
    return true;
  };
  ScaleShift positions;
  if (sights.empty() || !positions_under(R, &positions)) return out;
  // Over flat ground every frame centre decodes alike and carries the same offset, which no number of packets
  // averages: the fusion takes it as a posterior over that offset. Over relief the codes differ and their errors
  // partly average: a Gaussian floor of the prior's σ over √(distinct codes). Heights that are not 2-byte codes
  // carry no such error.
  const bool coded = std::all_of(heights.begin(), heights.end(), [](const Height& h) { return h.coded; });
  size_t steps = 1;
  for (size_t i = 1; i < heights.size(); ++i)
    steps += std::none_of(heights.begin(), heights.begin() + i, [&](const Height& h) { return h == heights[i]; });
  const bool one_step = coded && steps == 1;
  const std::vector<std::pair<double, double>> vertical_prior =
      one_step ? OffsetPrior(heights.front(), out.undulation_sigma) : std::vector<std::pair<double, double>>{};
  double floor_sd = 0;
  if (coded && !one_step) {
    for (const auto& h : heights) floor_sd += PriorSd(OffsetPrior(h, out.undulation_sigma));
    floor_sd /= static_cast<double>(heights.size()) * std::sqrt(static_cast<double>(steps));
  }
  const Eigen::Vector3d systematic(0, 0, floor_sd);
  out.elevation_steps = steps;
  out.encoding = !coded     ? ElevationEncoding::kExact
                 : one_step ? ElevationEncoding::kOneCode
                            : ElevationEncoding::kSeveralCodes;
  out.both_datums = heights.front().other.has_value();
  out.offset_prior_sd = coded ? PriorSd(OffsetPrior(heights.front(), out.undulation_sigma)) : 0.0;
  FrameCentreFusion fusion = FuseFrameCentres(R, positions, sights, min_inlier_threshold, systematic, vertical_prior);
  if (fusion.inliers >= 3 && fusion.sigma_m > 0) {
    // Refine the rotation on positions, lines of sight and attitudes together (frame centres off the track fix
    // the roll a straight track leaves to the ground plane, and spread ones the whole rotation), each weighed by
    // its own noise (the frame centres': about a fit of their own, OwnScatter), then fuse scale and translation
    // again: kept only if the frame centres then agree with the positions.
    JointMeasurements m;
    m.src = s_in, m.dst = d_in;
    m.position_sigma = fit.sigma * std::sqrt(s_in.size() / n_eff_p);
    m.attitudes = attitude.rotations;
    m.attitude_sigma_rad = attitude.EffectiveSigma();
    for (size_t i = 0; i < sights.size(); ++i)
      if (fusion.inlier_mask[i]) m.sights.push_back(sights[i]);
    const SightScatter own = OwnScatter(fit.sim, m.sights, fusion.sigma_m);
    m.sight_sigma = own.sigma_effective;
    const core::Sim3 joint = RefineSimilarity(fit.sim, m);
    const Eigen::Matrix3d R2 = joint.q.toRotationMatrix();
    ScaleShift positions2;
    if (positions_under(R2, &positions2)) {
      FrameCentreFusion again =
          FuseFrameCentres(R2, positions2, sights, min_inlier_threshold, systematic, vertical_prior);
      // The turn must also be one the positions and attitudes allow — a gross-error gate (χ², 3 dof, 99.99%):
      // frame centres whose errors are smooth along the track fit a similarity of their own too well and would
      // look precise. (Not 99.9%: the positions' rotation information ignores their errors' correlation and is
      // optimistic; a synthetic orbit's correct turn of 0.61° scored 20.8.)
      Eigen::Matrix3d info_pa = RotationInformation(d_in, m.position_sigma);
      if (!m.attitudes.empty())
        info_pa += Eigen::Matrix3d::Identity() / std::pow(m.attitude_sigma_rad, 2) * m.attitudes.size();
      const Eigen::Vector3d turn = LogRotation(R2 * R.transpose());
      const double turn_chi2 = turn.dot(info_pa * turn);
      spdlog::debug(
          "georef: frame centres' own σ {:.3f} m (effective {:.3f}, under the positions' rotation {:.3f}); "
          "joint refinement turned the rotation {:.3f}° (χ² {:.1f}); frame centres χ² {:.1f} → {:.1f}",
          own.sigma, own.sigma_effective, fusion.sigma_m * std::sqrt(fusion.inliers / fusion.effective_samples),
          turn.norm() * 180 / M_PI, turn_chi2, fusion.chi2, again.chi2);
      out.turn = GeorefFrameCentres::Turn{turn.norm() * 180 / M_PI, turn_chi2, again.used && turn_chi2 <= 21.11};
      if (out.turn->applied) {
        out.sim.q = joint.q;
        fusion = again;
        out.sigma = own.sigma_effective;
      }
    }
  }
  out.fusion = fusion;
  if (fusion.used) {
    out.sim.s = fusion.fused.scale;
    out.sim.t = fusion.fused.translation;
    for (size_t i = 0; i < sights.size(); ++i)
      if (fusion.inlier_mask[i]) out.points.push_back(sights[i].frame_centre);
    if (!(out.sigma > 0)) out.sigma = fusion.sigma_m * std::sqrt(fusion.inliers / fusion.effective_samples);
    spdlog::info("georef: {} frame centres at their slant range fused (σ {:.2f} m per axis, χ² {:.1f})", fusion.inliers,
                 fusion.sigma_m, fusion.chi2);
  } else {
    spdlog::info("georef: frame centres not used: {} (σ {:.2f} m, χ² {:.1f})", fusion.Why(), fusion.sigma_m,
                 fusion.chi2);
  }
  return out;
}

}  // namespace fmv3d::geo
