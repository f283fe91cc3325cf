// Replicate summaries and the tie rule (eval/replicates.h).

#include "eval/replicates.h"

#include <gtest/gtest.h>

namespace facedyn::eval {
namespace {

TEST(SpreadOf, MeanSampleSdAndRange) {
  const Spread s = SpreadOf({1.0, 2.0, 3.0});
  EXPECT_EQ(s.count, 3);
  EXPECT_DOUBLE_EQ(s.mean, 2.0);
  EXPECT_DOUBLE_EQ(s.sd, 1.0);
  EXPECT_DOUBLE_EQ(s.min, 1.0);
  EXPECT_DOUBLE_EQ(s.max, 3.0);
  EXPECT_EQ(SpreadOf({}).count, 0);
}

TEST(CompareLowerIsBetter, InsideTheSpreadIsATie) {
  const Spread low = SpreadOf({1.0, 1.1, 0.9});   // sd 0.1
  const Spread close = SpreadOf({1.05, 1.15, 0.95});
  const Spread high = SpreadOf({2.0, 2.1, 1.9});
  EXPECT_EQ(CompareLowerIsBetter(low, close), "tie");
  EXPECT_EQ(CompareLowerIsBetter(low, high), "lower");
  EXPECT_EQ(CompareLowerIsBetter(high, low), "higher");
  // A wide spread swallows a difference that narrow ones would show.
  EXPECT_EQ(CompareLowerIsBetter(SpreadOf({0.5, 1.5, 2.5}), SpreadOf({1.6, 1.7, 1.8})), "tie");
  EXPECT_EQ(CompareLowerIsBetter(SpreadOf({1.49, 1.5, 1.51}), SpreadOf({1.6, 1.7, 1.8})), "lower");
  EXPECT_EQ(CompareLowerIsBetter(SpreadOf({1.0, 1.0}), high), "too few replicates");
}

TEST(SummariseRemovalReplicates, MatchesTakesByNameAndJudgesFAgainstBaselines) {
  std::vector<Json> studies;
  for (double f : {0.10, 0.11, 0.12}) {
    Json methods = {{"F_exact_targets", {{"jiggle_mean_mm", f}}},
                    {"lowpass", {{"jiggle_mean_mm", 0.20}}},
                    {"moving_average", {{"jiggle_mean_mm", f + 0.005}}}};
    studies.push_back({{"removal", Json::array({{{"take", "neutral 11 Hz"},
                                                 {"protocol", "held-out frequency"},
                                                 {"methods", methods}}})}});
  }
  const Json summary = SummariseRemovalReplicates(studies);
  ASSERT_EQ(summary["removal"].size(), 1u);
  const Json& take = summary["removal"][0];
  EXPECT_EQ(take["take"], "neutral 11 Hz");
  EXPECT_EQ(take["protocol"], "held-out frequency");
  EXPECT_NEAR(take["methods"]["F_exact_targets"]["mean_mm"].get<double>(), 0.11, 1e-9);
  EXPECT_NEAR(take["methods"]["F_exact_targets"]["sd_mm"].get<double>(), 0.01, 1e-9);
  std::map<std::string, std::string> verdict;
  for (const Json& v : take["verdicts"]) verdict[v["against"]] = v["error_is"];
  EXPECT_EQ(verdict.at("lowpass"), "lower");
  EXPECT_EQ(verdict.at("moving_average"), "tie");  // 0.005 mm inside a 0.01 mm spread
}

}  // namespace
}  // namespace facedyn::eval
