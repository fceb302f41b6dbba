// synth --degrade: the spec's parser refuses malformed input with the spec in the message, and each kind takes
// away what automatic matching needs (sharpness, contrast, texture) — measured on a rendered-like texture.
#include "fmv3d/synth/degrade.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::synth {
namespace {

using ::testing::HasSubstr;

cv::Mat Texture() {
  cv::Mat im(360, 640, CV_8UC3);
  std::mt19937 rng(3);
  cv::randu(im, cv::Scalar::all(0), cv::Scalar::all(255));
  cv::GaussianBlur(im, im, cv::Size(5, 5), 1.0);
  return im;
}

double Sharpness(const cv::Mat& im) {
  cv::Mat grey, lap;
  cv::cvtColor(im, grey, cv::COLOR_BGR2GRAY);
  cv::Laplacian(grey, lap, CV_64F);
  cv::Scalar mean, sd;
  cv::meanStdDev(lap, mean, sd);
  return sd[0] * sd[0];
}

double Contrast(const cv::Mat& im) {
  cv::Scalar mean, sd;
  cv::meanStdDev(im, mean, sd);
  return sd[0];
}

TEST(SynthDegrade, ParsesSpecs) {
  const auto d = ParseDegradation("3,7:blur");
  ASSERT_EQ(d.size(), 2u);
  EXPECT_EQ(d[0].frame, 3);
  EXPECT_EQ(d[1].frame, 7);
  EXPECT_EQ(d[1].kind, Degradation::kBlur);
  EXPECT_EQ(ParseDegradation("0:blank").at(0).kind, Degradation::kBlank);
  EXPECT_EQ(ParseDegradation("12:contrast").at(0).kind, Degradation::kContrast);
  for (const std::string bad : {"3", "3:smear", "a:blur", "-1:blur", ":blur", "3,,x:blur", "1.5:blur"}) {
    try {
      (void)ParseDegradation(bad);
      ADD_FAILURE() << bad << " accepted";
    } catch (const Error& e) {
      EXPECT_THAT(e.what(), HasSubstr("--degrade \"" + bad + "\"")) << bad;
    }
  }
}

TEST(SynthDegrade, EachKindRemovesWhatMatchingNeeds) {
  const cv::Mat original = Texture();
  cv::Mat blur = original.clone(), contrast = original.clone(), blank = original.clone();
  Degrade(Degradation::kBlur, &blur);
  Degrade(Degradation::kContrast, &contrast);
  Degrade(Degradation::kBlank, &blank);
  EXPECT_LT(Sharpness(blur), 0.05 * Sharpness(original));
  EXPECT_LT(Contrast(contrast), 0.02 * Contrast(original) + 1);
  const cv::Rect inner(20, 20, 600, 320);
  EXPECT_EQ(Contrast(blank(inner)), 0.0);
  EXPECT_GT(Contrast(blank(cv::Rect(0, 0, 640, 5))), 10.0);  // a thin textured border remains
}

}  // namespace
}  // namespace fmv3d::synth
