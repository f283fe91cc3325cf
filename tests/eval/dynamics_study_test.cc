// Option checks of the dynamics validation study (eval/dynamics_study.h). The study itself runs in
// bench/dynamics_bench and, small, in `facedyn demo` (tests/app/cli_test.cc).

#include "eval/dynamics_study.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace facedyn::eval {
namespace {

using ::testing::HasSubstr;

TEST(DynamicsStudyOptions, DefaultsAreOneAmplitudeAndThePapersNetwork) {
  const DynamicsStudyOptions options;
  EXPECT_TRUE(options.Check().ok());
  EXPECT_EQ(options.train_amplitudes_mm, std::vector<double>{2.0});
  EXPECT_EQ(options.test_amplitude_mm, 2.0);
  EXPECT_EQ(options.removal_hidden_units, 128);
  EXPECT_EQ(options.removal_weight_decay, 0.0);
  EXPECT_EQ(options.removal_input_noise_std, 0.0);
}

TEST(DynamicsStudyOptions, CheckNamesTheField) {
  auto message = [](auto change) {
    DynamicsStudyOptions options;
    change(&options);
    return options.Check().message();
  };
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->train_amplitudes_mm.clear(); }),
              HasSubstr("train_amplitudes_mm"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) {
                o->train_amplitudes_mm = {1.0, 0.0};
              }),
              HasSubstr("train_amplitudes_mm"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->train_amplitudes_mm = {60.0}; }),
              HasSubstr("train_amplitudes_mm"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->test_amplitude_mm = -1.0; }),
              HasSubstr("test_amplitude_mm"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->removal_hidden_units = 0; }),
              HasSubstr("removal_hidden_units"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->removal_weight_decay = -1e-4; }),
              HasSubstr("removal_weight_decay"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->removal_input_noise_std = -0.1; }),
              HasSubstr("removal_input_noise_std"));
  // A held-out expression or motion must really be held out, and be one the simulator has.
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->held_out_expressions = {"smile"}; }),
              HasSubstr("held_out_expressions: \"smile\" is trained on"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->held_out_expressions = {"speech"}; }),
              HasSubstr("held_out_expressions"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->held_out_expression_hz = 40; }),
              HasSubstr("held_out_expression_hz"));
  EXPECT_THAT(message([](DynamicsStudyOptions* o) { o->held_out_motions = {"platform"}; }),
              HasSubstr("held_out_motions: \"platform\" is not walk, run or jump"));
  DynamicsStudyOptions several;
  several.train_amplitudes_mm = {1.5, 2.0, 2.5};
  EXPECT_TRUE(several.Check().ok());
}

}  // namespace
}  // namespace facedyn::eval
