#include "fmv3d/features/feature_io.h"

#include <gtest/gtest.h>

#include <fstream>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::features {
namespace {

FeatureSet RandomFeatures(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1000);
  FeatureSet f;
  f.image_name = "clip-000012.png";
  f.width = 1280;
  f.height = 720;
  f.keypoints.resize(n);
  f.descriptors.resize(n, 128);
  f.colors.resize(n);
  for (int i = 0; i < n; ++i) {
    f.keypoints[i] = {u(rng), u(rng), u(rng) / 100, u(rng) / 200};
    for (int d = 0; d < 128; ++d) f.descriptors(i, d) = static_cast<uint8_t>(rng() & 0xff);
    f.colors[i] = {uint8_t(rng()), uint8_t(rng()), uint8_t(rng())};
  }
  return f;
}

std::string ErrorOf(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

void Truncate(const std::filesystem::path& p, size_t keep) {
  std::ifstream in(p, std::ios::binary);
  std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(s.data(), static_cast<std::streamsize>(std::min(keep, s.size())));
}

TEST(FeatureIo, FeaturesRoundTrip) {
  test::TempDir dir;
  const auto f = RandomFeatures(321, 7);
  const auto path = FeaturePath(dir.path(), f.image_name);
  EXPECT_EQ(path.filename(), "clip-000012.feat");
  WriteFeatures(f, path);
  const auto g = ReadFeatures(path);
  EXPECT_EQ(g.image_name, f.image_name);
  EXPECT_EQ(g.width, 1280);
  EXPECT_EQ(g.height, 720);
  ASSERT_EQ(g.keypoints.size(), 321u);
  for (size_t i = 0; i < g.keypoints.size(); ++i) {
    EXPECT_EQ(g.keypoints[i].x, f.keypoints[i].x);
    EXPECT_EQ(g.keypoints[i].orientation, f.keypoints[i].orientation);
    EXPECT_EQ(g.colors[i], f.colors[i]);
  }
  EXPECT_TRUE(g.descriptors == f.descriptors);
  EXPECT_EQ(g.contrast_threshold, 0.0);

  // Keypoints only: the same keypoints and colours, no descriptors; a truncated descriptor block still fails.
  const auto k = ReadFeatures(path, /*descriptors=*/false);
  ASSERT_EQ(k.keypoints.size(), 321u);
  EXPECT_EQ(k.descriptors.rows(), 0);
  EXPECT_EQ(k.keypoints[320].y, f.keypoints[320].y);
  EXPECT_EQ(k.colors[320], f.colors[320]);

  // The contrast threshold the keypoints were found with is kept (a resumed run reports it unchanged).
  auto faint = RandomFeatures(4, 5);
  faint.contrast_threshold = 0.04 * 0.5 * 0.5;
  WriteFeatures(faint, dir / "faint.feat");
  EXPECT_EQ(ReadFeatures(dir / "faint.feat").contrast_threshold, 0.04 * 0.5 * 0.5);

  // Empty feature sets (a blank frame) are legal.
  FeatureSet empty;
  empty.image_name = "sky.png";
  empty.width = 10;
  empty.height = 10;
  WriteFeatures(empty, dir / "sky.feat");
  EXPECT_EQ(ReadFeatures(dir / "sky.feat").keypoints.size(), 0u);
}

TEST(FeatureIo, CorruptFeatureFilesThrowClearErrors) {
  test::TempDir dir;
  const auto path = dir / "a.feat";
  WriteFeatures(RandomFeatures(50, 3), path);
  const auto size = std::filesystem::file_size(path);
  Truncate(path, size - 20);
  EXPECT_NE(ErrorOf([&] { ReadFeatures(path); }).find("truncated"), std::string::npos);
  Truncate(path, 10);
  EXPECT_NE(ErrorOf([&] { ReadFeatures(path); }).find("a.feat"), std::string::npos);
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << "P6\n1280 720\n255\nnot a feature file at all";
  }
  EXPECT_NE(ErrorOf([&] { ReadFeatures(path); }).find("wrong magic"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { ReadFeatures(dir / "missing.feat"); }).find("cannot open"), std::string::npos);
  // A huge corrupt count must not allocate, just fail.
  WriteFeatures(RandomFeatures(5, 3), path);
  {
    std::fstream io(path, std::ios::binary | std::ios::in | std::ios::out);
    io.seekp(8 + 4 + 4 + 4);
    const uint32_t huge = 0x7fffffff;
    io.write(reinterpret_cast<const char*>(&huge), 4);
  }
  EXPECT_NE(ErrorOf([&] { ReadFeatures(path); }).find("do not fit"), std::string::npos);
  // Wrong version.
  WriteFeatures(RandomFeatures(5, 3), path);
  {
    std::fstream io(path, std::ios::binary | std::ios::in | std::ios::out);
    io.seekp(8);
    const uint32_t v = 99;
    io.write(reinterpret_cast<const char*>(&v), 4);
  }
  EXPECT_NE(ErrorOf([&] { ReadFeatures(path); }).find("version 99"), std::string::npos);
  // Version 1 (no contrast threshold) is still read: the same bytes without those 8.
  const auto v1 = RandomFeatures(6, 2);
  WriteFeatures(v1, path);
  {
    std::ifstream in(path, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    in.close();
    const size_t at = 8 + 4 + 4 + 4 + 4 + 4 + v1.image_name.size();
    bytes.erase(at, 8);
    const uint32_t one = 1;
    bytes.replace(8, 4, reinterpret_cast<const char*>(&one), 4);
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << bytes;
  }
  const auto r1 = ReadFeatures(path);
  EXPECT_EQ(r1.keypoints.size(), 6u);
  EXPECT_EQ(r1.contrast_threshold, 0.0);
  EXPECT_TRUE(r1.descriptors == v1.descriptors);
}

TEST(FeatureIo, MatchesRoundTripAndValidation) {
  test::TempDir dir;
  std::vector<VerifiedPair> pairs(3);
  for (uint32_t i = 0; i < 3; ++i) {
    auto& p = pairs[i];
    p.image_id1 = i + 1;
    p.image_id2 = i + 3;
    p.F = Eigen::Matrix3d::Random();
    p.E = Eigen::Matrix3d::Random();
    p.H = Eigen::Matrix3d::Random();
    p.R = Eigen::Matrix3d::Random();
    p.t = Eigen::Vector3d::Random();
    p.has_pose = i == 1;
    p.median_triangulation_angle_deg = 3.5 * i;
    p.num_putative = 100 + i;
    p.num_inliers_F = 80;
    p.num_inliers_E = 70;
    p.num_inliers_H = 10 * i;
    p.geometry = static_cast<PairGeometry>(i + 1);
    for (uint32_t k = 0; k < 20 * i; ++k) p.inliers.push_back({k, k * 2});
  }
  const auto path = MatchesPath(dir.path());
  WriteMatches(pairs, path);
  const auto q = ReadMatches(path);
  ASSERT_EQ(q.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(q[i].image_id1, pairs[i].image_id1);
    EXPECT_EQ(q[i].image_id2, pairs[i].image_id2);
    EXPECT_EQ(q[i].geometry, pairs[i].geometry);
    EXPECT_EQ(q[i].has_pose, pairs[i].has_pose);
    EXPECT_EQ(q[i].F, pairs[i].F);
    EXPECT_EQ(q[i].R, pairs[i].R);
    EXPECT_EQ(q[i].t, pairs[i].t);
    EXPECT_EQ(q[i].num_inliers_H, pairs[i].num_inliers_H);
    EXPECT_EQ(q[i].median_triangulation_angle_deg, pairs[i].median_triangulation_angle_deg);
    ASSERT_EQ(q[i].inliers.size(), pairs[i].inliers.size());
    for (size_t k = 0; k < q[i].inliers.size(); ++k) EXPECT_EQ(q[i].inliers[k].idx2, pairs[i].inliers[k].idx2);
  }
  EXPECT_NO_THROW(ValidateMatches(q, {100, 100, 100, 100, 100}, "m"));
  EXPECT_NE(ErrorOf([&] {
              ValidateMatches(q, {100, 100, 100, 100}, "m");
            }).find("beyond the 4 frames"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { ValidateMatches(q, {100, 100, 100, 100, 30}, "m"); }).find("keypoint"), std::string::npos);

  Truncate(path, std::filesystem::file_size(path) - 9);
  EXPECT_NE(ErrorOf([&] { ReadMatches(path); }).find("truncated"), std::string::npos);
  WriteFeatures(RandomFeatures(5, 1), path);
  EXPECT_NE(ErrorOf([&] { ReadMatches(path); }).find("not an fmv3d match file"), std::string::npos);
}

// The match file written pair by pair has the bytes of the one written from the whole vector, and read pair by
// pair gives what ReadMatches gives, with the same errors on a broken file.
TEST(FeatureIo, MatchesStreamedEqualMatchesWrittenWhole) {
  test::TempDir dir;
  std::vector<VerifiedPair> pairs(5);
  for (uint32_t i = 0; i < pairs.size(); ++i) {
    auto& p = pairs[i];
    p.image_id1 = i + 1;
    p.image_id2 = 2 * i + 2;
    p.F = Eigen::Matrix3d::Random();
    p.R = Eigen::Matrix3d::Random();
    p.t = Eigen::Vector3d::Random();
    p.num_putative = 50 + i;
    p.geometry = static_cast<PairGeometry>(i % 4);
    for (uint32_t k = 0; k < 7 * i; ++k) p.inliers.push_back({k, k + i});
  }
  const auto whole = dir / "whole.bin", streamed = dir / "streamed.bin";
  WriteMatches(pairs, whole);
  {
    MatchFileWriter w(streamed);
    for (const auto& p : pairs) w.Add(p);
    EXPECT_FALSE(std::filesystem::exists(streamed));  // only once finished
    w.Finish();
    EXPECT_EQ(w.count(), pairs.size());
  }
  EXPECT_EQ(core::ReadTextFile(streamed), core::ReadTextFile(whole));
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()), std::filesystem::directory_iterator()), 2);

  MatchFileReader r(whole);
  const auto all = ReadMatches(whole);
  ASSERT_EQ(r.size(), all.size());
  for (size_t k = all.size(); k-- > 0;) {  // any order
    EXPECT_EQ(r.ids(k), std::make_pair(all[k].image_id1, all[k].image_id2));
    const VerifiedPair p = r.Read(k);
    EXPECT_EQ(p.F, all[k].F);
    EXPECT_EQ(p.t, all[k].t);
    EXPECT_EQ(p.geometry, all[k].geometry);
    EXPECT_EQ(p.num_putative, all[k].num_putative);
    ASSERT_EQ(p.inliers.size(), all[k].inliers.size());
    for (size_t m = 0; m < p.inliers.size(); ++m) EXPECT_EQ(p.inliers[m].idx2, all[k].inliers[m].idx2);
  }

  {
    MatchFileWriter unfinished(dir / "unfinished.bin");
    unfinished.Add(pairs[0]);
  }
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()), std::filesystem::directory_iterator()), 2);
  for (const uintmax_t cut : {9, 600}) {
    Truncate(whole, std::filesystem::file_size(whole) - cut);
    const std::string error = ErrorOf([&] { ReadMatches(whole); });
    EXPECT_NE(error.find("truncated"), std::string::npos) << error;
    EXPECT_EQ(ErrorOf([&] { MatchFileReader{whole}; }), error);
  }
}

}  // namespace
}  // namespace fmv3d::features
