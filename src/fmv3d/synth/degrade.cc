#include "fmv3d/synth/degrade.h"

#include <opencv2/imgproc.hpp>
#include <sstream>

#include "fmv3d/core/error.h"

namespace fmv3d::synth {

const char* DegradationName(Degradation d) {
  switch (d) {
    case Degradation::kBlur:
      return "blur";
    case Degradation::kContrast:
      return "contrast";
    case Degradation::kBlank:
      return "blank";
  }
  return "";
}

std::vector<FrameDegradation> ParseDegradation(const std::string& spec) {
  const auto colon = spec.rfind(':');
  if (colon == std::string::npos)
    throw Error("--degrade \"" + spec + "\": expected FRAMES:KIND, e.g. 5,6:blur (KIND: blur, contrast, blank)");
  const std::string kind_s = spec.substr(colon + 1);
  Degradation kind;
  if (kind_s == "blur")
    kind = Degradation::kBlur;
  else if (kind_s == "contrast")
    kind = Degradation::kContrast;
  else if (kind_s == "blank")
    kind = Degradation::kBlank;
  else
    throw Error("--degrade \"" + spec + "\": unknown kind \"" + kind_s + "\" (blur, contrast, blank)");
  std::vector<FrameDegradation> out;
  std::stringstream in(spec.substr(0, colon));
  for (std::string item; std::getline(in, item, ',');) {
    size_t used = 0;
    int frame = -1;
    try {
      frame = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != item.size() || frame < 0)
      throw Error("--degrade \"" + spec + "\": \"" + item + "\" is not a frame index (0, 1, ...)");
    out.push_back({frame, kind});
  }
  if (out.empty()) throw Error("--degrade \"" + spec + "\": no frame given");
  return out;
}

void Degrade(Degradation kind, cv::Mat* image) {
  cv::Mat& im = *image;
  switch (kind) {
    case Degradation::kBlur: {
      const int len = std::max(9, im.cols / 8) | 1;
      cv::Mat kernel = cv::Mat::zeros(len, len, CV_32F);
      for (int i = 0; i < len; ++i) kernel.at<float>(i, i) = 1.0f / len;
      cv::Mat out;
      cv::filter2D(im, out, -1, kernel, cv::Point(-1, -1), 0, cv::BORDER_REFLECT);
      im = out;
      break;
    }
    case Degradation::kContrast: {
      const cv::Scalar mean = cv::mean(im);
      cv::Mat f;
      im.convertTo(f, CV_32F);
      cv::Mat m(im.size(), f.type(), mean);
      f = m + 0.03 * (f - m);
      f.convertTo(im, im.type());
      break;
    }
    case Degradation::kBlank: {
      const cv::Scalar mean = cv::mean(im);
      const cv::Rect patch(im.cols / 20, im.rows / 20, im.cols - im.cols / 10, im.rows - im.rows / 10);
      im(patch).setTo(mean);
      break;
    }
  }
}

}  // namespace fmv3d::synth
