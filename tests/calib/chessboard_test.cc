#include "fmv3d/calib/chessboard.h"

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/io/image_io.h"
#include "test_util.h"

namespace fmv3d::calib {
namespace {

// Renders views of a planar chessboard through a known camera (with distortion) by inverse mapping: each
// sub-pixel's ray (Camera::Unproject removes the distortion exactly) is intersected with the board plane
// and coloured by the square it hits; 3x3 supersampling, a slight blur and noise.
// (The issue asks for `fmv3d synth` to render these; synth/ is not available to this branch yet, so the
// scene is rendered here.)
class BoardRenderer {
 public:
  BoardRenderer(const core::Camera& cam, const BoardSpec& board) : cam_(cam), board_(board) {
    rays_.resize(size_t(cam.width) * cam.height * kSs * kSs);
    tbb::parallel_for(0, cam.height, [&](int v) {
      for (int u = 0; u < cam.width; ++u)
        for (int j = 0; j < kSs; ++j)
          for (int i = 0; i < kSs; ++i) {
            const Eigen::Vector2d uv(u + (i + 0.5) / kSs, v + (j + 0.5) / kSs);  // pixel centres at +0.5
            const Eigen::Vector3d r = cam.Unproject(uv);
            rays_[Index(u, v, i, j)] = Eigen::Vector2f(float(r.x()), float(r.y()));
          }
    });
  }

  // Board-to-camera pose: x_cam = R X_board + t, board corners at (c·square, r·square, 0).
  cv::Mat Render(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, unsigned seed) const {
    cv::Mat img(cam_.height, cam_.width, CV_32F);
    const Eigen::Matrix3d Rt = R.transpose();
    const Eigen::Vector3d C = -Rt * t;
    const double sq = board_.square;
    tbb::parallel_for(0, cam_.height, [&](int v) {
      for (int u = 0; u < cam_.width; ++u) {
        double sum = 0;
        for (int j = 0; j < kSs; ++j)
          for (int i = 0; i < kSs; ++i) {
            const Eigen::Vector2f& r = rays_[Index(u, v, i, j)];
            const Eigen::Vector3d d = Rt * Eigen::Vector3d(r.x(), r.y(), 1.0);
            double value = 70;  // background
            if (std::abs(d.z()) > 1e-12) {
              const double lambda = -C.z() / d.z();
              if (lambda > 0) {
                const double x = (C.x() + lambda * d.x()) / sq, y = (C.y() + lambda * d.y()) / sq;
                // Squares span [-1, cols] x [-1, rows] in square units; a white margin of one square.
                if (x >= -2 && x < board_.cols + 1 && y >= -2 && y < board_.rows + 1) {
                  value = 235;
                  if (x >= -1 && x < board_.cols && y >= -1 && y < board_.rows &&
                      ((int(std::floor(x)) + int(std::floor(y))) & 1) == 0)
                    value = 20;
                }
              }
            }
            sum += value;
          }
        img.at<float>(v, u) = float(sum / (kSs * kSs));
      }
    });
    cv::GaussianBlur(img, img, cv::Size(0, 0), 0.6);
    cv::Mat noise(img.size(), CV_32F);
    cv::RNG rng(seed);
    rng.fill(noise, cv::RNG::NORMAL, 0, 2.0);
    img += noise;
    cv::Mat out;
    img.convertTo(out, CV_8U);
    return out;
  }

 private:
  static constexpr int kSs = 3;
  size_t Index(int u, int v, int i, int j) const { return ((size_t(v) * cam_.width + u) * kSs + j) * kSs + i; }
  core::Camera cam_;
  BoardSpec board_;
  std::vector<Eigen::Vector2f> rays_;
};

TEST(Chessboard, SyntheticViewsRecoverKnownIntrinsics) {
  core::Camera truth;
  truth.width = 640;
  truth.height = 480;
  truth.f = 560;
  truth.aspect = 1.003;
  truth.u0 = 327.3;
  truth.v0 = 236.8;
  truth.k1 = -0.18;
  truth.k2 = 0.05;
  truth.p1 = 0.0008;
  truth.p2 = -0.0005;
  const BoardSpec board = BoardSpec::Parse("9x6", 0.03);
  const BoardRenderer renderer(truth, board);

  // 12 views: board centre in front at 0.4–0.6 m, tilted up to ~35°, spread over the image.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> tilt(-0.6, 0.6), spin(-0.4, 0.4), dist(0.38, 0.55), shift(-0.06, 0.06);
  std::vector<BoardDetection> detections;
  const Eigen::Vector3d centre(4 * board.square, 2.5 * board.square, 0);  // middle of the inner corners
  for (int k = 0; detections.size() < 12 && k < 40; ++k) {
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(spin(rng), Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(tilt(rng), Eigen::Vector3d::UnitX()) *
                               Eigen::AngleAxisd(tilt(rng), Eigen::Vector3d::UnitY()))
                                  .toRotationMatrix();
    const Eigen::Vector3d t = Eigen::Vector3d{shift(rng), shift(rng), dist(rng)} - R * centre;
    const cv::Mat img = renderer.Render(R, t, 100 + k);
    BoardDetection d = DetectChessboard(img, board, "view" + std::to_string(k));
    if (!d.found) continue;  // a view that leaves the image
    // Detected corners match the true projections (OpenCV convention: −0.5).
    double worst = 0;
    for (int r = 0; r < board.rows; ++r)
      for (int c = 0; c < board.cols; ++c) {
        const Eigen::Vector2d p = truth.Project(R * Eigen::Vector3d(c * board.square, r * board.square, 0) + t);
        const cv::Point2f q = d.corners[r * board.cols + c];
        worst = std::max(worst, std::hypot(q.x - (p.x() - 0.5), q.y - (p.y() - 0.5)));
      }
    EXPECT_LT(worst, 0.3) << d.name;
    detections.push_back(d);
  }
  ASSERT_EQ(detections.size(), 12u);
  const CalibrationResult res = Calibrate(detections, board);
  const core::Camera& c = res.camera;
  std::printf(
      "synthetic: f %.3f (true %.3f), aspect %.5f, pp (%.3f, %.3f) (true %.1f, %.1f), k1 %.5f k2 %.5f "
      "p1 %.6f p2 %.6f, RMS %.3f px\n",
      c.f, truth.f, c.aspect, c.u0, c.v0, truth.u0, truth.v0, c.k1, c.k2, c.p1, c.p2, res.rms);
  EXPECT_LT(std::abs(c.f - truth.f) / truth.f, 0.002);
  EXPECT_NEAR(c.aspect, truth.aspect, 0.002);
  EXPECT_NEAR(c.u0, truth.u0, 1.0);
  EXPECT_NEAR(c.v0, truth.v0, 1.0);
  EXPECT_NEAR(c.k1, truth.k1, 0.01);
  EXPECT_NEAR(c.k2, truth.k2, 0.05);
  EXPECT_NEAR(c.p1, truth.p1, 0.001);
  EXPECT_NEAR(c.p2, truth.p2, 0.001);
  EXPECT_LT(res.rms, 0.2);
  EXPECT_EQ(res.per_image_rms.size(), 12u);
  // Per-image corners (+0.5 convention) and residuals: one per board corner, and each image's residual vectors
  // give back its RMS.
  ASSERT_EQ(res.corners.size(), 12u);
  ASSERT_EQ(res.residuals.size(), 12u);
  for (size_t v = 0; v < res.residuals.size(); ++v) {
    ASSERT_EQ(res.corners[v].size(), size_t(board.cols * board.rows));
    ASSERT_EQ(res.residuals[v].size(), res.corners[v].size());
    double sq = 0;
    for (const auto& r : res.residuals[v]) sq += r.squaredNorm();
    EXPECT_NEAR(std::sqrt(sq / res.residuals[v].size()), res.per_image_rms[v], 1e-3 + 0.01 * res.per_image_rms[v]) << v;
    EXPECT_NEAR(res.corners[v][0].x(), detections[v].corners[0].x + 0.5, 1e-6);
  }
  // The standard deviations are honest: the true values lie within a few sigma.
  EXPECT_LT(std::abs(c.f - truth.f), 5 * res.stddev[core::kF] + 0.05);
  EXPECT_GT(res.stddev[core::kF], 0);
}

TEST(Chessboard, RealOpenCvSampleBoards) {
  FMV3D_REQUIRE_SHARED_DATA("calib/opencv-chessboard/left01.jpg");
  const auto dir = test::SharedData() / "calib/opencv-chessboard";
  const BoardSpec board = BoardSpec::Parse("9x6", 0.025);
  std::vector<BoardDetection> detections;
  for (const char* n : {"left01", "left02", "left03", "left04", "left05", "left06", "left07", "left08", "left09",
                        "left11", "left12", "left13", "left14"})
    detections.push_back(DetectChessboard(io::ReadImage(dir / (std::string(n) + ".jpg")), board, n));
  const CalibrationResult res = Calibrate(detections, board);
  EXPECT_EQ(res.used.size(), 13u);
  EXPECT_TRUE(res.rejected.empty());
  EXPECT_LT(res.rms, 0.5);
  for (double r : res.per_image_rms) EXPECT_LT(r, 0.5);
  // OpenCV's own calibration of these images (with k3) has fx ≈ fy ≈ 536 px, cx ≈ 342, cy ≈ 235.
  EXPECT_NEAR(res.camera.f, 536, 536 * 0.01);
  EXPECT_NEAR(res.camera.u0, 342.4, 3);
  EXPECT_NEAR(res.camera.v0, 235.5, 3);
  EXPECT_LT(res.camera.k1, -0.2);  // strong barrel
}

TEST(Chessboard, NotEnoughBoardsAndBadSpecs) {
  EXPECT_THROW(BoardSpec::Parse("9by6", 0.025), Error);
  EXPECT_THROW(BoardSpec::Parse("9x6", -1), Error);
  EXPECT_THROW(BoardSpec::Parse("1x6", 0.025), Error);
  const BoardSpec board = BoardSpec::Parse("9x6", 0.025);
  const cv::Mat blank(240, 320, CV_8UC3, cv::Scalar(128, 128, 128));
  std::vector<BoardDetection> d;
  d.reserve(4);
  for (int i = 0; i < 4; ++i) d.push_back(DetectChessboard(blank, board, "blank" + std::to_string(i)));
  for (const auto& x : d) EXPECT_FALSE(x.found);
  try {
    Calibrate(d, board);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("at least 3"), std::string::npos) << e.what();
  }
}

TEST(Chessboard, DistortionFieldFigure) {
  core::Camera c = core::Camera::Pinhole(640, 480, 500);
  c.k1 = -0.01;  // small: drawn at exactly x10
  const cv::Mat fig = DrawDistortionField(c, 10);
  EXPECT_EQ(fig.cols, 1000);
  EXPECT_EQ(fig.rows, 750);
  // Arrows are drawn in blue; at least some pixels carry it.
  cv::Mat blue;
  cv::inRange(fig, cv::Scalar(150, 0, 0), cv::Scalar(255, 120, 80), blue);
  EXPECT_GT(cv::countNonZero(blue), 500);
}

}  // namespace
}  // namespace fmv3d::calib
