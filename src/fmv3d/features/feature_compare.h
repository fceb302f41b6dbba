// How close two feature sets of one image are (e.g. tiled vs whole-image SIFT, sift_memory.h): which keypoints of
// a reference set the other set holds identically, or within a position tolerance, and how far their descriptors
// are apart.
#pragma once

#include <cstddef>

#include "fmv3d/features/types.h"

namespace fmv3d::features {

struct KeypointAgreement {
  size_t reference = 0, other = 0;  // keypoint counts
  size_t identical = 0;             // same position, scale, orientation (bit for bit) and descriptor
  size_t within = 0;                // position within the tolerance, scale within 1%, orientation within 0.01 rad
  double mean_descriptor_distance = 0, max_descriptor_distance = 0;  // L2 of the uint8 descriptors, `within` pairs
  double identical_share() const { return reference ? double(identical) / reference : 1.0; }
  double within_share() const { return reference ? double(within) / reference : 1.0; }
};

// For each keypoint of `reference`, the closest-descriptor keypoint of `other` that agrees within `tolerance_px`.
KeypointAgreement CompareKeypoints(const FeatureSet& reference, const FeatureSet& other, double tolerance_px = 0.01);

// Sums of two agreements (counts added, distances weighted by the `within` counts).
KeypointAgreement Accumulate(const KeypointAgreement& a, const KeypointAgreement& b);

}  // namespace fmv3d::features
