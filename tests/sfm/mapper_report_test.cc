// report/sparse.json's "mapper" object from the typed mapper statistics.
#include "fmv3d/sfm/mapper_report.h"

#include <gtest/gtest.h>

namespace fmv3d::sfm {
namespace {

TEST(MapperReport, GuidedCompletionNotRunIsOneFlag) {
  EXPECT_EQ(ToJson(std::vector<GuidedCompletionPass>{}), nlohmann::json({{"run", false}}));
}

TEST(MapperReport, GuidedCompletionPassStatesItsBoundAndWhatWasPruned) {
  GuidedCompletionPass first, second;
  first.stats.candidates = 200;
  first.stats.accepted = 30;
  first.options.false_accept_rate = 0.01;
  first.removed_after_adjustment = 4;
  second.observations_before = 1234;
  const nlohmann::json j = ToJson(std::vector<GuidedCompletionPass>{first, second});
  ASSERT_EQ(j.size(), 2u);
  EXPECT_EQ(j[0].at("observations_added"), 30);
  EXPECT_DOUBLE_EQ(j[0].at("expected_false_additions_at_most").get<double>(), 2.0);
  EXPECT_EQ(j[0].at("removed_after_adjustment"), 4);
  EXPECT_FALSE(j[1].contains("removed_after_adjustment"));
  EXPECT_EQ(j[1].at("observations_before"), 1234);
}

TEST(MapperReport, TracksOfTheLargestModelOnlyWhenThereIsOne) {
  TrackSummary t;
  t.union_find_tracks = 10;
  EXPECT_FALSE(ToJson(t).contains("model_mean_track_length"));
  t.largest_model = TrackCoverage{};
  t.largest_model->points = 4;
  t.largest_model->observations = 14;
  EXPECT_DOUBLE_EQ(ToJson(t).at("model_mean_track_length").get<double>(), 3.5);
  t.largest_model->points = 0;  // an empty model: no division by zero
  EXPECT_DOUBLE_EQ(ToJson(t).at("model_mean_track_length").get<double>(), 0.0);
}

TEST(MapperReport, TimingsKeepTheReportsNames) {
  MapperStats s;
  s.seconds.init = 1;
  s.seconds.registration = 2;
  s.seconds.total = 9;
  const nlohmann::json j = ToJson(s);
  EXPECT_EQ(j.at("seconds").at("initial_pair"), 1.0);
  EXPECT_EQ(j.at("seconds").at("absolute_pose"), 2.0);
  EXPECT_EQ(j.at("seconds").at("total"), 9.0);
  EXPECT_EQ(j.at("guided_completion"), nlohmann::json({{"run", false}}));
}

}  // namespace
}  // namespace fmv3d::sfm
