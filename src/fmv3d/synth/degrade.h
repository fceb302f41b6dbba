// Frames degraded on purpose so that automatic matching cannot register them (tests of the operator's tie
// points): `fmv3d synth --degrade 5,6:blur --degrade 12:contrast`. Applied to the rendered image before it is
// written; the truth (poses, tracks) is unchanged.
//   blur      heavy linear motion blur, a kernel 1/8 of the image width long, diagonal
//   contrast  contrast cut to 3% about the mean (a few grey levels of texture left after 8-bit quantisation)
//   blank     a texture-less patch (the image's mean colour) over the central 90% x 90% of the frame
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace fmv3d::synth {

enum class Degradation { kBlur, kContrast, kBlank };
const char* DegradationName(Degradation d);

struct FrameDegradation {
  int frame = 0;  // index from 0
  Degradation kind = Degradation::kBlur;
};

// "3,7:blur" → {3, blur}, {7, blur}. Throws fmv3d::Error naming the spec when it is malformed.
std::vector<FrameDegradation> ParseDegradation(const std::string& spec);

// Degrades an 8-bit BGR (or grey) image in place.
void Degrade(Degradation kind, cv::Mat* image);

}  // namespace fmv3d::synth
