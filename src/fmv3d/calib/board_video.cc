#include "fmv3d/calib/board_video.h"

#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "fmv3d/core/error.h"
#include "fmv3d/ingest/video_reader.h"

namespace fmv3d::calib {

void VideoBoardOptions::Check() const {
  if (samples < 3) throw Error("calibrate: --video-samples must be at least 3");
  if (max_views < 3) throw Error("calibrate: --max-views must be at least 3");
}

namespace {

// The board's four outer corners, normalised by the image size, ordered by angle about their centroid starting
// from the one nearest the image's top-left: the same pose gives the same vector whichever corner the detector
// numbered first.
Eigen::Matrix<double, 8, 1> PoseDescriptor(const BoardDetection& d, const BoardSpec& board) {
  const int n = board.cols * board.rows;
  const std::array<cv::Point2f, 4> raw = {d.corners[0], d.corners[board.cols - 1], d.corners[n - 1],
                                          d.corners[n - board.cols]};
  Eigen::Vector2d c(0, 0);
  std::array<Eigen::Vector2d, 4> p;
  for (int k = 0; k < 4; ++k) {
    p[k] = Eigen::Vector2d(raw[k].x / d.image_size.width, raw[k].y / d.image_size.height);
    c += p[k] / 4;
  }
  std::sort(p.begin(), p.end(), [&](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return std::atan2(a.y() - c.y(), a.x() - c.x()) < std::atan2(b.y() - c.y(), b.x() - c.x());
  });
  int first = 0;
  for (int k = 1; k < 4; ++k)
    if (p[k].sum() < p[first].sum()) first = k;
  Eigen::Matrix<double, 8, 1> v;
  for (int k = 0; k < 4; ++k) v.segment<2>(2 * k) = p[(first + k) % 4];
  return v;
}

// Area of the quadrilateral of the four outer corners (shoelace), normalised.
double ApparentSize(const Eigen::Matrix<double, 8, 1>& v) {
  double a = 0;
  for (int k = 0; k < 4; ++k) {
    const int j = (k + 1) % 4;
    a += v(2 * k) * v(2 * j + 1) - v(2 * j) * v(2 * k + 1);
  }
  return std::abs(a) / 2;
}

}  // namespace

std::vector<size_t> ChooseSpreadViews(const std::vector<BoardDetection>& views, const BoardSpec& board,
                                      size_t max_views) {
  std::vector<size_t> found;
  std::vector<Eigen::Matrix<double, 8, 1>> desc;
  for (size_t i = 0; i < views.size(); ++i)
    if (views[i].found && views[i].corners.size() == size_t(board.cols * board.rows)) {
      found.push_back(i);
      desc.push_back(PoseDescriptor(views[i], board));
    }
  if (found.size() <= max_views) return found;
  size_t first = 0;
  for (size_t k = 1; k < found.size(); ++k)
    if (ApparentSize(desc[k]) > ApparentSize(desc[first])) first = k;
  std::vector<double> nearest(found.size(), std::numeric_limits<double>::infinity());
  std::vector<size_t> chosen;
  for (size_t next = first; chosen.size() < max_views;) {
    chosen.push_back(next);
    for (size_t k = 0; k < found.size(); ++k) nearest[k] = std::min(nearest[k], (desc[k] - desc[next]).norm());
    next = static_cast<size_t>(std::max_element(nearest.begin(), nearest.end()) - nearest.begin());
  }
  std::vector<size_t> out;
  for (size_t k : chosen) out.push_back(found[k]);
  std::sort(out.begin(), out.end());
  return out;
}

VideoBoardViews DetectBoardsInVideo(const std::filesystem::path& video, const BoardSpec& board,
                                    const VideoBoardOptions& options, const std::set<std::string>& exclude) {
  options.Check();
  ingest::VideoReader reader(video);
  const int64_t hint = reader.info().frame_count_hint;
  const int64_t step = hint > 0 ? std::max<int64_t>(1, hint / options.samples) : 1;
  const std::string stem = video.stem().string();
  std::vector<BoardDetection> detections;
  std::vector<cv::Mat> images;
  VideoBoardViews out;
  ingest::VideoFrame frame;
  while (out.sampled < options.samples && reader.Read(&frame)) {
    if (frame.index % step != 0) continue;
    ++out.sampled;
    const std::string name = fmt::format("{}-{:06d}.png", stem, frame.index);
    if (exclude.count(name)) {
      out.excluded.push_back(name);
      continue;
    }
    BoardDetection d = DetectChessboard(frame.image, board, name);
    if (!d.found) continue;
    detections.push_back(std::move(d));
    images.push_back(frame.image.clone());
  }
  if (out.sampled == 0)
    throw Error(video.string() + ": no frame could be decoded" +
                (reader.warning().empty() ? "" : " (" + reader.warning() + ")"));
  out.found = static_cast<int>(detections.size());
  for (size_t i : ChooseSpreadViews(detections, board, static_cast<size_t>(options.max_views))) {
    out.detections.push_back(std::move(detections[i]));
    out.images.push_back(std::move(images[i]));
  }
  return out;
}

}  // namespace fmv3d::calib
