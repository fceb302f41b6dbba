#include "fmv3d/geo/trajectory.h"

#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"

namespace fmv3d::geo {

CameraTrajectory::CameraTrajectory(std::vector<TrajectoryKnot> knots, double max_gap) {
  std::stable_sort(knots.begin(), knots.end(),
                   [](const TrajectoryKnot& a, const TrajectoryKnot& b) { return a.time < b.time; });
  for (auto& k : knots) {
    if (!std::isfinite(k.time) || !k.centre.allFinite()) continue;
    if (!knots_.empty() && k.time <= knots_.back().time) continue;
    k.rotation.normalize();
    knots_.push_back(k);
  }
  if (knots_.size() < 2) throw Error("camera trajectory: fewer than 2 registered frames with distinct times");
  if (max_gap > 0) {
    max_gap_ = max_gap;
  } else {
    std::vector<double> d;
    for (size_t i = 1; i < knots_.size(); ++i) d.push_back(knots_[i].time - knots_[i - 1].time);
    max_gap_ = 2.5 * core::Median(std::move(d));
  }
}

std::optional<TrajectoryKnot> CameraTrajectory::At(double t) const {
  if (!(t >= knots_.front().time && t <= knots_.back().time)) return std::nullopt;
  // i: the last knot at or before t (i + 1 exists unless t is the last knot's time).
  size_t i = static_cast<size_t>(
      std::upper_bound(knots_.begin(), knots_.end(), t, [](double v, const TrajectoryKnot& k) { return v < k.time; }) -
      knots_.begin() - 1);
  if (i + 1 == knots_.size()) --i;
  auto linked = [&](size_t a) { return knots_[a + 1].time - knots_[a].time <= max_gap_; };  // a → a+1
  if (!linked(i)) return std::nullopt;
  // Stencil of up to 4 knots around [i, i+1], never across a gap: one on each side first, then a second on
  // whichever side still has knots (at the ends of the span or of a gap).
  size_t lo = i, hi = i + 1;
  for (int pass = 0; pass < 2 && hi - lo + 1 < 4; ++pass) {
    if (lo > 0 && linked(lo - 1) && hi - lo + 1 < 4) --lo;
    if (hi + 1 < knots_.size() && linked(hi) && hi - lo + 1 < 4) ++hi;
  }
  TrajectoryKnot out;
  out.time = t;
  out.centre.setZero();
  for (size_t a = lo; a <= hi; ++a) {  // Lagrange basis on the stencil
    double w = 1;
    for (size_t b = lo; b <= hi; ++b)
      if (b != a) w *= (t - knots_[b].time) / (knots_[a].time - knots_[b].time);
    out.centre += w * knots_[a].centre;
  }
  const double u = (t - knots_[i].time) / (knots_[i + 1].time - knots_[i].time);
  out.rotation = knots_[i].rotation.slerp(u, knots_[i + 1].rotation).normalized();
  return out;
}

}  // namespace fmv3d::geo
