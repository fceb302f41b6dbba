// Large OpenCV matrices on their own huge-page mappings (io/huge_pages.h): the same values, the same layout,
// small matrices left to OpenCV's allocator.
#include "fmv3d/io/huge_pages.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace fmv3d::io {
namespace {

TEST(HugePages, LargeMatricesGetTheirOwnMappingSmallOnesDoNot) {
  // The blur of a 2,048 x 1,536 float image before the allocator is installed, for comparison.
  cv::Mat source(1536, 2048, CV_32F);
  cv::randu(source, 0.0f, 1.0f);
  cv::Mat expected;
  cv::GaussianBlur(source, expected, cv::Size(0, 0), 1.6);

  UseHugePagesForLargeMatrices(size_t{4} << 20);
  UseHugePagesForLargeMatrices(size_t{1} << 40);  // later calls change nothing
  const cv::MatAllocator* standard = cv::Mat::getStdAllocator();

  cv::Mat large(1536, 2048, CV_32F);  // 12 MiB
  ASSERT_NE(large.u, nullptr);
  EXPECT_NE(large.u->currAllocator, standard);
  EXPECT_TRUE(large.isContinuous());
  EXPECT_EQ(large.step[0], 2048 * sizeof(float));
  EXPECT_EQ(large.u->size, size_t{1536} * 2048 * sizeof(float));
  cv::Mat blurred;
  cv::GaussianBlur(source, blurred, cv::Size(0, 0), 1.6);
  EXPECT_NE(blurred.u->currAllocator, standard);
  EXPECT_EQ(cv::norm(blurred, expected, cv::NORM_INF), 0.0);

  cv::Mat small(100, 100, CV_8UC3);
  EXPECT_EQ(small.u->currAllocator, standard);

  // Views, copies and release behave as with any matrix.
  cv::Mat roi = large(cv::Rect(10, 20, 300, 200));
  roi.setTo(7.0f);
  EXPECT_EQ(large.at<float>(20, 10), 7.0f);
  EXPECT_EQ(large.at<float>(219, 309), 7.0f);
  large.release();
  EXPECT_EQ(roi.at<float>(0, 0), 7.0f);  // the view keeps the mapping alive
  const cv::Mat copy = roi.clone();
  roi.release();
  EXPECT_EQ(copy.at<float>(199, 299), 7.0f);

  // A 3-D matrix is laid out densely too.
  const int sizes[] = {64, 256, 256};
  cv::Mat cube(3, sizes, CV_32F, cv::Scalar(2.0f));
  EXPECT_NE(cube.u->currAllocator, standard);
  EXPECT_EQ(cube.step[2], sizeof(float));
  EXPECT_EQ(cube.step[1], 256 * sizeof(float));
  EXPECT_EQ(cube.step[0], size_t{256} * 256 * sizeof(float));
  EXPECT_EQ(cv::sum(cube)[0], 2.0 * 64 * 256 * 256);
}

TEST(HugePages, MatricesFreedInAReuseScopeServeTheNextOfTheSameSize) {
  UseHugePagesForLargeMatrices(size_t{4} << 20);
  constexpr size_t kMiB = size_t{1} << 20;
  EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 0U);
  {
    const ScopedMatrixReuse reuse;
    cv::Mat a(1536, 2048, CV_32F, cv::Scalar(1.0f));  // 12 MiB: six huge pages
    const uchar* where = a.data;
    a.release();
    EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 12 * kMiB);

    cv::Mat b(2048, 1536, CV_32F);  // the same bytes in another shape: the kept mapping
    EXPECT_EQ(b.data, where);
    EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 0U);
    b.setTo(3.0f);
    EXPECT_EQ(cv::sum(b)[0], 3.0 * 2048 * 1536);
    b.release();

    // 23.4 MiB rounds up to 24: no kept mapping of that size, so the kept 12 MiB go before a new one is mapped.
    cv::Mat c(3000, 2048, CV_32F);
    EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 0U);
    c.release();
    EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 24 * kMiB);

    { const ScopedMatrixReuse inner; }  // an inner scope's end keeps them for the outer one
    EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 24 * kMiB);
    cv::Mat small(100, 100, CV_8UC3);
    small.release();  // OpenCV's own allocation: never kept
    EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 24 * kMiB);
  }
  EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 0U);  // the last scope returned them
  cv::Mat d(1536, 2048, CV_32F);
  d.release();
  EXPECT_EQ(ScopedMatrixReuse::KeptBytes(), 0U);  // outside a scope nothing is kept
}

}  // namespace
}  // namespace fmv3d::io
