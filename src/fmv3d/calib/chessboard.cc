#include "fmv3d/calib/chessboard.h"

#include <cmath>
#include <cstdio>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"

namespace fmv3d::calib {

BoardSpec BoardSpec::Parse(const std::string& text, double square) {
  BoardSpec b;
  char x = 0, extra = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &b.cols, &x, &b.rows, &extra) != 3 || (x != 'x' && x != 'X'))
    throw Error("--board: expected inner corners as COLSxROWS (e.g. 9x6), got '" + text + "'");
  b.square = square;
  b.Check();
  return b;
}

void BoardSpec::Check() const {
  if (cols < 2 || rows < 2 || cols > 100 || rows > 100) throw Error("--board: needs at least 2x2 inner corners");
  if (!(square > 0)) throw Error("--square: must be a positive length");
}

BoardDetection DetectChessboard(const cv::Mat& image, const BoardSpec& board, const std::string& name) {
  BoardDetection d;
  d.name = name;
  d.image_size = image.size();
  cv::Mat grey;
  if (image.channels() == 3)
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  else
    grey = image;
  const cv::Size pattern(board.cols, board.rows);
  // The classic detector + cornerSubPix is the reference for accuracy on sharp boards; the sector-based one
  // finds boards the classic one misses (blur, strong distortion).
  d.found =
      cv::findChessboardCorners(grey, pattern, d.corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
  if (d.found) {
    // Search window scaled to the board's square size in the image, capped so it never spans two corners.
    double min_dist = 1e9;
    for (int r = 0; r < board.rows; ++r)
      for (int c = 0; c + 1 < board.cols; ++c) {
        const auto& a = d.corners[r * board.cols + c];
        const auto& b = d.corners[r * board.cols + c + 1];
        min_dist = std::min(min_dist, double(std::hypot(a.x - b.x, a.y - b.y)));
      }
    const int win = std::max(2, std::min(11, int(min_dist * 0.4)));
    cv::cornerSubPix(grey, d.corners, cv::Size(win, win), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS | cv::TermCriteria::COUNT, 50, 1e-4));
  } else {
    d.found = cv::findChessboardCornersSB(grey, pattern, d.corners, cv::CALIB_CB_EXHAUSTIVE | cv::CALIB_CB_ACCURACY);
  }
  if (!d.found) d.corners.clear();
  return d;
}

CalibrationResult Calibrate(const std::vector<BoardDetection>& detections, const BoardSpec& board) {
  board.Check();
  CalibrationResult res;
  res.board = board;
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  cv::Size size;
  std::vector<cv::Point3f> grid;
  for (int r = 0; r < board.rows; ++r)
    for (int c = 0; c < board.cols; ++c) grid.emplace_back(float(c * board.square), float(r * board.square), 0.f);
  for (const auto& d : detections) {
    if (!d.found) {
      res.rejected.push_back(d.name);
      continue;
    }
    if (size.area() == 0) size = d.image_size;
    if (d.image_size != size)
      throw Error(d.name + ": image size " + std::to_string(d.image_size.width) + "x" +
                  std::to_string(d.image_size.height) +
                  " differs from the first image's; calibrate one camera "
                  "mode at a time");
    object.push_back(grid);
    image.push_back(d.corners);
    res.used.push_back(d.name);
  }
  if (image.size() < 3)
    throw Error("calibrate: the board was found in " + std::to_string(image.size()) +
                " image(s); at least 3 views are needed");

  cv::Mat K = cv::Mat::eye(3, 3, CV_64F), dist = cv::Mat::zeros(5, 1, CV_64F);
  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat std_intr, std_extr, per_view;
  const int flags = cv::CALIB_FIX_K3;  // the seed's model: k1 k2 p1 p2, free aspect
  res.rms = cv::calibrateCamera(object, image, size, K, dist, rvecs, tvecs, std_intr, std_extr, per_view, flags,
                                cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12));
  for (int i = 0; i < per_view.rows; ++i) res.per_image_rms.push_back(per_view.at<double>(i));
  for (size_t v = 0; v < image.size(); ++v) {
    std::vector<cv::Point2f> projected;
    cv::projectPoints(object[v], rvecs[v], tvecs[v], K, dist, projected);
    auto& corners = res.corners.emplace_back();
    auto& residuals = res.residuals.emplace_back();
    for (size_t k = 0; k < projected.size(); ++k) {
      corners.emplace_back(image[v][k].x + 0.5, image[v][k].y + 0.5);
      residuals.emplace_back(projected[k].x - image[v][k].x, projected[k].y - image[v][k].y);
    }
  }

  core::Camera& cam = res.camera;
  cam.width = size.width;
  cam.height = size.height;
  const double fx = K.at<double>(0, 0), fy = K.at<double>(1, 1);
  cam.f = fy;
  cam.aspect = fx / fy;
  cam.u0 = K.at<double>(0, 2) + 0.5;  // OpenCV integer pixel centres → ours (+0.5)
  cam.v0 = K.at<double>(1, 2) + 0.5;
  cam.k1 = dist.at<double>(0);
  cam.k2 = dist.at<double>(1);
  cam.p1 = dist.at<double>(2);
  cam.p2 = dist.at<double>(3);
  // stdDeviationsIntrinsics: fx fy cx cy k1 k2 p1 p2 k3 ...; the aspect's by first-order propagation
  // (ignoring the fx–fy correlation, which OpenCV does not return).
  auto sd = [&](int i) { return std_intr.rows > i ? std_intr.at<double>(i) : 0.0; };
  res.stddev[core::kF] = sd(1);
  res.stddev[core::kAspect] = std::hypot(sd(0) / fy, fx * sd(1) / (fy * fy));
  res.stddev[core::kU0] = sd(2);
  res.stddev[core::kV0] = sd(3);
  res.stddev[core::kK1] = sd(4);
  res.stddev[core::kK2] = sd(5);
  res.stddev[core::kP1] = sd(6);
  res.stddev[core::kP2] = sd(7);
  return res;
}

cv::Mat DrawDistortionField(const core::Camera& camera, double exaggeration, int grid_cells) {
  const int w = camera.width, h = camera.height;
  // Draw at a comfortable size whatever the sensor resolution.
  const double scale = 1000.0 / std::max(w, h);
  const int W = int(std::lround(w * scale)), H = int(std::lround(h * scale));
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  cv::rectangle(img, cv::Rect(0, 0, W, H), cv::Scalar(0, 0, 0), 1);
  const double step = double(std::max(w, h)) / grid_cells;
  struct Arrow {
    cv::Point2d at, disp;
  };
  std::vector<Arrow> arrows;
  double max_disp = 0;
  for (double v = step / 2; v < h; v += step) {
    for (double u = step / 2; u < w; u += step) {
      // (u, v) is where an ideal pinhole would image the ray; the lens moves it to Project(ray).
      const Eigen::Vector3d ray((u - camera.u0) / camera.fx(), (v - camera.v0) / camera.fy(), 1.0);
      const Eigen::Vector2d disp = camera.Project(ray) - Eigen::Vector2d(u, v);
      max_disp = std::max(max_disp, disp.norm());
      arrows.push_back({cv::Point2d(u, v), cv::Point2d(disp.x(), disp.y())});
    }
  }
  // A strong lens exaggerated x10 would draw arrows across the whole image: then the factor is lowered so
  // the longest arrow spans 1.5 grid cells, and the label says so.
  double factor = exaggeration;
  if (max_disp * factor > 1.5 * step) factor = 1.5 * step / max_disp;
  for (const auto& a : arrows) {
    const cv::Point2d p = a.at * scale, q = (a.at + a.disp * factor) * scale;
    cv::circle(img, p, 2, cv::Scalar(0, 0, 0), cv::FILLED, cv::LINE_AA);
    const double len = std::hypot(q.x - p.x, q.y - p.y);
    cv::arrowedLine(img, p, q, cv::Scalar(200, 60, 0), 1, cv::LINE_AA, 0, len > 0 ? std::min(0.3, 8.0 / len) : 0.1);
  }
  const cv::Point2d pp(camera.u0 * scale, camera.v0 * scale);
  cv::drawMarker(img, pp, cv::Scalar(0, 0, 255), cv::MARKER_CROSS, 20, 2);
  char text[240];
  if (factor == exaggeration)
    std::snprintf(text, sizeof(text), "distortion x%.0f  (max %.2f px)  k1=%.4f k2=%.4f p1=%.5f p2=%.5f", exaggeration,
                  max_disp, camera.k1, camera.k2, camera.p1, camera.p2);
  else
    std::snprintf(text, sizeof(text),
                  "distortion x%.2f (x%.0f would overlap; max %.2f px)  k1=%.4f k2=%.4f p1=%.5f p2=%.5f", factor,
                  exaggeration, max_disp, camera.k1, camera.k2, camera.p1, camera.p2);
  cv::putText(img, text, cv::Point(10, H - 12), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  return img;
}

cv::Mat DrawCorners(const cv::Mat& image, const BoardDetection& detection, const BoardSpec& board) {
  cv::Mat out;
  if (image.channels() == 1)
    cv::cvtColor(image, out, cv::COLOR_GRAY2BGR);
  else
    out = image.clone();
  if (detection.found)
    cv::drawChessboardCorners(out, cv::Size(board.cols, board.rows), detection.corners, true);
  else
    cv::putText(out, "board not found", cv::Point(10, 30), cv::FONT_HERSHEY_SIMPLEX, 0.8, cv::Scalar(0, 0, 255), 2);
  return out;
}

}  // namespace fmv3d::calib
