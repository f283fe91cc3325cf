// Replicate summaries and the tie rule (eval/replicates.h).

#include "eval/replicates.h"

#include <gtest/gtest.h>

#include <map>
#include <string>

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

// The demo's stages, one per seed: removal per protocol with the lower reference, Fig. 7's
// residual, the walk synthesis and the retargeting, each judged for the learned method only.
TEST(SummariseDemoReplicates, EverySectionPerProtocolWithVerdicts) {
  std::vector<Json> stages;
  for (double d : {0.0, 0.01, 0.02}) {
    Json stage;
    stage["removal"] = {{"exact_offsets_removed_mm", 0.05 + d},
                        {"methods",
                         {{"F", {{"jiggle_mean_mm", 0.10 + d}}},
                          {"lowpass", {{"jiggle_mean_mm", 0.30 + d}}}}}};
    stage["removal_walk"] = {{"exact_offsets_removed_mm", 0.04},
                             {"methods",
                              {{"F", {{"jiggle_mean_mm", 0.50 + d}}},
                               {"lowpass", {{"jiggle_mean_mm", 0.20 + d}}}}}};
    stage["synthesis"] = {
        {"resynthesis",
         {{"resynthesis_residual_mm", 0.3 + d}, {"removed_without_synthesis_mm", 1.0}}},
        {"resynthesis_performance",
         {{"resynthesis_residual_mm", 0.2 + d},
          {"modal_resynthesis_residual_mm", 0.1 + d},
          {"removed_without_synthesis_mm", 0.8}}},
        {"walk",
         {{"methods",
           {{"H", {{"offset_mean_mm", 0.2}}}, {"no_dynamics", {{"offset_mean_mm", 0.21}}}}}}}};
    stage["retarget"] = {{"methods",
                          {{"H_B_retarget", {{"offset_mean_mm", 0.40 + 5 * d}}},
                           {"modal_B_retarget", {{"offset_mean_mm", 0.15 + d}}},
                           {"naive_delta_transfer", {{"offset_mean_mm", 0.30}}},
                           {"no_dynamics", {{"offset_mean_mm", 0.70}}}}}};
    stages.push_back(stage);
  }
  const Json summary = SummariseDemoReplicates(stages, {1, 2, 3});
  EXPECT_EQ(summary["replicates"], 3);
  EXPECT_EQ(summary["seeds"], Json::array({1, 2, 3}));
  auto verdicts = [](const Json& take) {
    std::map<std::string, std::string> out;
    for (const Json& v : take["verdicts"]) out[v["method"].get<std::string>() + " vs " +
                                               v["against"].get<std::string>()] = v["error_is"];
    return out;
  };
  ASSERT_EQ(summary["removal"].size(), 2u);  // no removal_performance in these stages
  const Json& frequency = summary["removal"][0];
  EXPECT_EQ(frequency["take"], "removal");
  EXPECT_EQ(frequency["protocol"], "held-out platform frequency");
  EXPECT_NEAR(frequency["methods"]["lower_reference"]["mean_mm"].get<double>(), 0.06, 1e-9);
  EXPECT_NEAR(frequency["methods"]["F"]["sd_mm"].get<double>(), 0.01, 1e-9);
  EXPECT_EQ(verdicts(frequency).at("F vs lowpass"), "lower");
  EXPECT_EQ(verdicts(frequency).at("F vs lower_reference"), "higher");
  EXPECT_EQ(verdicts(summary["removal"][1]).at("F vs lowpass"), "higher");
  const Json& resynthesis = summary["resynthesis"][0];
  EXPECT_NEAR(resynthesis["methods"]["H_resynthesis_residual"]["mean_mm"].get<double>(), 0.31,
              1e-9);
  EXPECT_EQ(verdicts(resynthesis).at("H_resynthesis_residual vs removed_without_synthesis"),
            "lower");
  // Fig. 7 on the performance too; the modal resynthesis is judged, against the baseline only.
  ASSERT_EQ(summary["resynthesis"].size(), 2u);
  const Json& performance = summary["resynthesis"][1];
  EXPECT_EQ(performance["take"], "held-out performance (speech)");
  EXPECT_NEAR(performance["methods"]["modal_resynthesis_residual"]["mean_mm"].get<double>(), 0.11,
              1e-9);
  EXPECT_EQ(verdicts(performance).at("modal_resynthesis_residual vs removed_without_synthesis"),
            "lower");
  EXPECT_EQ(verdicts(performance).size(), 2u);
  // 0.2 against 0.21 with no spread: outside a zero spread, so lower (the rule, not a judgement).
  EXPECT_EQ(verdicts(summary["new_motion_synthesis"][0]).at("H vs no_dynamics"), "lower");
  const auto retarget = verdicts(summary["retarget"][0]);
  EXPECT_EQ(retarget.at("H_B_retarget vs naive_delta_transfer"), "higher");  // 0.45 +- 0.05
  EXPECT_EQ(retarget.at("H_B_retarget vs no_dynamics"), "lower");
  // The modal synthesis is a fitted method too: it gets verdicts, and is not a baseline of H's.
  EXPECT_EQ(retarget.at("modal_B_retarget vs naive_delta_transfer"), "lower");
  EXPECT_EQ(retarget.count("H_B_retarget vs modal_B_retarget"), 0u);
  EXPECT_EQ(retarget.size(), 4u);  // only the two fitted methods are judged
}

}  // namespace
}  // namespace facedyn::eval
