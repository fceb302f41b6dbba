// Screening of position fixes before they reach the frames: a fix that would georeference wrongly is dropped
// and counted, never used. Every reader (EXIF, GPMF, and any later one) screens its samples here, so the rules
// are the same for photos and videos.
//
// A fix is rejected when it has no latitude/longitude (kNoPosition, not an error: the source simply has none),
// is exactly (0, 0) (receivers write it before their first lock), lies outside the globe or states an altitude
// outside [−1000, 20000] m, says it has no lock (GPS fix < 2D, EXIF GPSStatus 'V'), or states a dilution of
// precision or a horizontal accuracy worse than the options allow.
#pragma once

#include <array>
#include <cstddef>
#include <string>

#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::telemetry {

enum class FixRejection { kNone, kNoPosition, kZeroFix, kOutOfRange, kNoLock, kPoorDop, kPoorAccuracy };
constexpr size_t kFixRejectionCount = 7;

// "no position", "(0, 0) fix", "out of range", "no lock", "DOP too large", "accuracy too poor".
const char* FixRejectionText(FixRejection r);

struct FixQualityOptions {
  double max_dop = 10;                  // GPS DOP above this: poor geometry (> 10 is "poor" in every table)
  double max_horizontal_accuracy = 30;  // metres (1σ) stated by the source
  void Check() const;                   // throws fmv3d::Error on non-positive bounds
};

FixRejection ScreenFix(const TelemetrySample& sample, const FixQualityOptions& options);

// How many fixes were kept and why the others were dropped.
struct FixCounts {
  size_t kept = 0;
  std::array<size_t, kFixRejectionCount> rejected{};  // indexed by FixRejection
  void Add(FixRejection r);
  size_t Rejected() const;  // every rejection except kNoPosition
  // "3 of 20 fixes dropped: 2 (0, 0) fix, 1 no lock" (empty when none was dropped).
  std::string Summary(const std::string& what = "fixes") const;
};

}  // namespace fmv3d::telemetry
