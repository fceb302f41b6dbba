// WS/manual/tiepoints.json: every kind of bad input gives a message naming the entry, nothing is written when
// anything is wrong, and what is written reads back identically.
#include "fmv3d/io/tiepoints.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

using ::testing::HasSubstr;

FrameTable Frames() {
  FrameTable t;
  t["a.png"] = {640, 360, 100};
  t["b.png"] = {640, 360, 100};
  t["c.png"] = {640, 360, 100};
  return t;
}

std::vector<std::string> Problems(const std::string& text) {
  std::vector<std::string> errors;
  const TiePoints t = ParseTiePoints(text, &errors);
  CheckTiePoints(t, Frames(), &errors);
  return errors;
}

std::string Doc(const std::string& body) { return R"({"format": "fmv3d-tiepoints", "version": 1, )" + body + "}"; }

const char* kTwo = R"("observations": [{"frame": "a.png", "x": 10.5, "y": 20}, {"frame": "b.png", "x": 11, "y": 21}])";

TEST(TiePoints, ValidFileRoundTrips) {
  const std::string text = Doc(std::string(R"("tie_points": [{"id": "t1", "label": "roof", )") + kTwo +
                               R"(}], "keypoints": [{"id": "k1", "frame": "c.png", "x": 0, "y": 360}],
      "deleted_matches": [{"frame1": "a.png", "frame2": "b.png", "feature1": 3, "feature2": 99}])");
  std::vector<std::string> errors;
  const TiePoints t = ParseTiePoints(text, &errors);
  CheckTiePoints(t, Frames(), &errors);
  ASSERT_TRUE(errors.empty()) << JoinErrors(errors);
  ASSERT_EQ(t.tie_points.size(), 1u);
  EXPECT_EQ(t.tie_points[0].label, "roof");
  EXPECT_DOUBLE_EQ(t.tie_points[0].observations[0].x, 10.5);
  EXPECT_EQ(t.keypoints.at(0).point.frame, "c.png");
  EXPECT_EQ(t.deleted_matches.at(0).feature2, 99u);
  test::TempDir dir("fmv3d-tiepoints");
  const FrameTable frames = Frames();
  WriteTiePoints(t, dir / "manual/tiepoints.json", &frames);
  const TiePoints back = ReadTiePoints(dir / "manual/tiepoints.json", &frames);
  EXPECT_EQ(TiePointsToJson(back), TiePointsToJson(t));
}

TEST(TiePoints, EveryBadInputNamed) {
  EXPECT_THAT(Problems("{not json").at(0), HasSubstr("not valid JSON"));
  EXPECT_THAT(Problems(R"({"format": "x", "version": 1})").at(0), HasSubstr("\"format\" must be"));
  EXPECT_THAT(Problems(R"({"format": "fmv3d-tiepoints", "version": 2})").at(0), HasSubstr("\"version\" must be 1"));
  EXPECT_THAT(Problems("[1, 2]").at(0), HasSubstr("JSON object"));
  // A frame that does not exist.
  auto e = Problems(Doc(R"("tie_points": [{"id": "t1", "observations": [{"frame": "a.png", "x": 1, "y": 1},
      {"frame": "zz.png", "x": 1, "y": 1}]}])"));
  ASSERT_EQ(e.size(), 1u);
  EXPECT_EQ(e[0], "tie point \"t1\", observation 2: frame \"zz.png\" is not in frames/frames.json");
  // Outside the image (x = width is the right edge and allowed; beyond it is not; negative is not).
  e = Problems(Doc(R"("tie_points": [{"id": "t1", "observations": [{"frame": "a.png", "x": 640.01, "y": 1},
      {"frame": "b.png", "x": 1, "y": -0.5}]}])"));
  ASSERT_EQ(e.size(), 2u);
  EXPECT_THAT(e[0], HasSubstr("(640.01, 1.00) is outside frame \"a.png\" (640x360)"));
  EXPECT_THAT(e[1], HasSubstr("observation 2"));
  // Fewer than 2 observations; two in the same frame.
  e = Problems(Doc(R"("tie_points": [{"id": "t1", "observations": [{"frame": "a.png", "x": 1, "y": 1}]}])"));
  ASSERT_EQ(e.size(), 1u);
  EXPECT_THAT(e[0], HasSubstr("needs ≥ 2"));
  e = Problems(Doc(R"("tie_points": [{"id": "t1", "observations": [{"frame": "a.png", "x": 1, "y": 1},
      {"frame": "a.png", "x": 2, "y": 2}]}])"));
  ASSERT_EQ(e.size(), 1u);
  EXPECT_THAT(e[0], HasSubstr("a second observation in frame \"a.png\""));
  // Duplicate and empty ids (across tie points and keypoints), missing fields, wrong types.
  e = Problems(Doc(
      std::string(R"("tie_points": [{"id": "t1", )") + kTwo + R"(}, {"id": "t1", )" + kTwo +
      R"(}], "keypoints": [{"id": "t1", "frame": "a.png", "x": 1, "y": 1}, {"id": "", "frame": "a.png", "x": 1, "y": 1}])"));
  ASSERT_EQ(e.size(), 3u);
  EXPECT_THAT(e[0], HasSubstr("duplicate id \"t1\""));
  EXPECT_THAT(e[1], HasSubstr("keypoint \"t1\": duplicate id"));
  EXPECT_THAT(e[2], HasSubstr("\"id\" is empty"));
  e = Problems(
      Doc(R"("tie_points": [{"observations": []}, 7], "keypoints": [{"id": "k", "frame": 3, "x": "1", "y": null}])"));
  EXPECT_GE(e.size(), 4u);
  EXPECT_THAT(JoinErrors(e, 100), HasSubstr("\"id\" is missing"));
  EXPECT_THAT(JoinErrors(e, 100), HasSubstr("\"frame\" must be a string"));
  EXPECT_THAT(JoinErrors(e, 100), HasSubstr("\"x\" must be a number"));
  EXPECT_THAT(Problems(Doc(R"("tie_points": {"id": "t"})")).at(0), HasSubstr("\"tie_points\" must be an array"));
  // Deleted matches: same frame twice, negative index, index beyond the frame's keypoints, unknown frame.
  e = Problems(Doc(R"("deleted_matches": [{"frame1": "a.png", "frame2": "a.png", "feature1": 1, "feature2": 2},
      {"frame1": "a.png", "frame2": "b.png", "feature1": -1, "feature2": 2},
      {"frame1": "a.png", "frame2": "b.png", "feature1": 100, "feature2": 2},
      {"frame1": "a.png", "frame2": "q.png", "feature1": 1, "feature2": 2}])"));
  ASSERT_EQ(e.size(), 4u) << JoinErrors(e, 100);
  EXPECT_THAT(e[0], HasSubstr("the same frame"));
  EXPECT_THAT(e[1], HasSubstr("must be a keypoint index"));
  EXPECT_THAT(e[2], HasSubstr("feature 100 of frame \"a.png\" does not exist (it has 100 keypoints)"));
  EXPECT_THAT(e[3], HasSubstr("frame \"q.png\" is not in frames/frames.json"));
}

TEST(TiePoints, NothingWrittenHalfWay) {
  test::TempDir dir("fmv3d-tiepoints");
  const auto path = dir / "tiepoints.json";
  const FrameTable frames = Frames();
  TiePoints good;
  good.tie_points.push_back({"t1", "", {{"a.png", 1, 1}, {"b.png", 2, 2}}});
  WriteTiePoints(good, path, &frames);
  const std::string before = core::ReadTextFile(path);
  TiePoints bad = good;
  bad.tie_points.push_back({"t2", "", {{"a.png", 1, 1}, {"nope.png", 2, 2}}});
  try {
    WriteTiePoints(bad, path, &frames);
    FAIL() << "a tie point in a missing frame was written";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("not saved"));
    EXPECT_THAT(e.what(), HasSubstr("nope.png"));
  }
  EXPECT_EQ(core::ReadTextFile(path), before);
  bad = good;
  bad.tie_points[0].observations.pop_back();
  EXPECT_THROW(WriteTiePoints(bad, path, &frames), Error);
  EXPECT_EQ(core::ReadTextFile(path), before);
  // The reader refuses the same content with the file's name in the message.
  core::WriteTextFile(dir / "bad.json", Doc(R"("tie_points": [{"id": "x", "observations": []}])"));
  try {
    (void)ReadTiePoints(dir / "bad.json", &frames);
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("bad.json: tie point \"x\": has 0 observation(s)"));
  }
}

}  // namespace
}  // namespace fmv3d::io
