// `facedyn dynamics train-removal | train | remove | train-synthesis | synthesize | retarget | eval
// | train-modal` end to end on small simulated takes: exit codes, files, JSON, and bad input.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;
using ::testing::HasSubstr;

std::string Facedyn(const std::string& args) { return FacedynExecutable() + " --quiet " + args; }

// Three 1 s simulated platform takes (7, 9 and 8 Hz) on the procedural face, made once.
const TempDir& Takes() {
  static const TempDir* dir = [] {
    auto* d = new TempDir();
    for (const char* hz : {"7", "9", "8"}) {
      std::string out;
      const int rc = RunCommand(Facedyn(std::string("sim perform --expression neutral --motion "
                                                    "platform --seconds 1 --hz ") +
                                        hz + " --out " + d->Join(std::string("p") + hz)),
                                &out);
      EXPECT_EQ(rc, 0) << out;
    }
    return d;
  }();
  return *dir;
}

TEST(DynamicsCli, TrainRemoveSynthesizeRetargetEvaluate) {
  const TempDir& takes = Takes();
  TempDir dir;
  std::string out;
  ASSERT_EQ(
      RunCommand(
          Facedyn("dynamics train-removal --takes " + takes.Join("p7") + " " + takes.Join("p9") +
                  " --targets exact --epochs 3 --batch 4000 --out " + dir.Join("F.pt") + " --json"),
          &out),
      0)
      << out;
  const auto summary = nlohmann::json::parse(out.substr(out.find('{')));
  EXPECT_EQ(summary["epochs"], 3);
  EXPECT_GT(summary["training_rows"].get<long>(), 0);

  ASSERT_EQ(RunCommand(Facedyn("dynamics remove --take " + takes.Join("p8") + " --model " +
                               dir.Join("F.pt") + " --out " + dir.Join("removed")),
                       &out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(dir.Join("removed/dynamic_offset.pc2")));

  ASSERT_EQ(RunCommand(Facedyn("dynamics eval --pred " + dir.Join("removed") + " --truth " +
                               takes.Join("p8") + " --input " + takes.Join("p8") + " --json"),
                       &out),
            0)
      << out;
  const auto evaluation = nlohmann::json::parse(out.substr(out.find('{')));
  // prediction, no_removal, lowpass (cutoff by rule), moving_average, lowpass_oracle.
  EXPECT_EQ(evaluation["reports"].size(), 5u) << out;
  EXPECT_TRUE(evaluation["reports"].contains("lowpass_oracle")) << out;
  EXPECT_NEAR(evaluation["lowpass_cutoff_hz"].get<double>(), 8.0 / 3, 1e-9) << out;

  ASSERT_EQ(RunCommand(Facedyn("dynamics train-synthesis --takes " + takes.Join("p7") + " " +
                               takes.Join("p9") + " --removal-model " + dir.Join("F.pt") +
                               " --epochs 2 --out " + dir.Join("H.pt")),
                       &out),
            0)
      << out;
  ASSERT_EQ(RunCommand(Facedyn("dynamics synthesize --take " + dir.Join("removed") + " --motion " +
                               takes.Join("p9") + " --model " + dir.Join("H.pt") + " --out " +
                               dir.Join("synth")),
                       &out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(dir.Join("synth/quasistatic.pc2")));
  ASSERT_EQ(RunCommand(Facedyn("dynamics retarget --source " + takes.Join("p9") + " --model " +
                               dir.Join("H.pt") + " --expression smile --out " +
                               dir.Join("retarget") + " --naive-out " + dir.Join("naive")),
                       &out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(dir.Join("retarget/take.json")));
  EXPECT_TRUE(std::filesystem::exists(dir.Join("naive/dynamic_offset.pc2")));

  // A synthesis model is not a removal model, and says so.
  EXPECT_EQ(RunCommand(Facedyn("dynamics remove --take " + takes.Join("p8") + " --model " +
                               dir.Join("H.pt") + " --out " + dir.Join("bad")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("is a synthesis model, expected a removal model"));
}

// F and H trained together: held takes with estimated targets, a talking take with none.
TEST(DynamicsCli, TrainJointWritesBothModelsAndReportsTheCycle) {
  const TempDir& takes = Takes();
  TempDir dir;
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("sim perform --expression speech --motion platform --seconds 1 "
                               "--hz 8 --seed 4 --out " +
                               dir.Join("speech")),
                       &out),
            0)
      << out;
  const std::string common = "dynamics train --takes " + takes.Join("p7") + " " + takes.Join("p9") +
                             " --performances " + dir.Join("speech") +
                             " --epochs 2 --synthesis-epochs 2 --joint-steps 20 --out-removal " +
                             dir.Join("F.pt") + " --out-synthesis " + dir.Join("H.pt");
  ASSERT_EQ(RunCommand(Facedyn(common + " --json"), &out), 0) << out;
  const auto summary = nlohmann::json::parse(out.substr(out.find('{')));
  EXPECT_EQ(summary["joint"]["steps"], 20);
  EXPECT_GT(summary["joint"]["performance_frames"].get<long>(), 0);
  // One report per 100 steps (the last one short): losses of F, H and the cycle.
  EXPECT_EQ(summary["joint"]["cycle_loss_mm2"].size(), 1u);
  EXPECT_GT(summary["joint"]["cycle_loss_mm2"][0].get<double>(), 0.0);
  EXPECT_EQ(summary["removal"]["epochs"], 2);
  EXPECT_EQ(summary["synthesis"]["epochs"], 2);
  // Both files are the ordinary models the other commands take.
  ASSERT_EQ(RunCommand(Facedyn("dynamics remove --take " + takes.Join("p8") + " --model " +
                               dir.Join("F.pt") + " --out " + dir.Join("removed")),
                       &out),
            0)
      << out;
  ASSERT_EQ(RunCommand(Facedyn("dynamics synthesize --take " + dir.Join("removed") + " --motion " +
                               takes.Join("p9") + " --model " + dir.Join("H.pt") + " --out " +
                               dir.Join("synth")),
                       &out),
            0)
      << out;

  // Early stopping needs held-out rows of F and of the cycle, and 1 s takes have none (their
  // frames are all needed for training): refused by name, before any model is written. (The
  // choice of report is tested in tests/learn/mlp_pair_test; this checks the flag reaches it.)
  std::filesystem::remove(dir.Join("F.pt"));
  std::filesystem::remove(dir.Join("H.pt"));
  EXPECT_EQ(RunCommand(Facedyn(common + " --early-stopping"), &out), 1);
  EXPECT_THAT(out, HasSubstr("early stopping needs held-out rows"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("F.pt")));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("H.pt")));
  EXPECT_EQ(summary["joint"]["kept_report"].get<long>(), 0);  // without it: the last report
  EXPECT_TRUE(summary["joint"].contains("synthesis_validation_loss_mm2"));

  // The simulator's exact targets are not a capture's: refused by name.
  EXPECT_NE(RunCommand(Facedyn(common + " --targets exact"), &out), 0);
  EXPECT_THAT(out, HasSubstr("--targets"));
  // A performance folder that is not there is named.
  EXPECT_EQ(RunCommand(Facedyn("dynamics train --takes " + takes.Join("p7") + " --performances " +
                               dir.Join("nowhere") + " --out-removal " + dir.Join("F2.pt") +
                               " --out-synthesis " + dir.Join("H2.pt")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("nowhere"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("F2.pt")));
}

// The modal model through the CLI: trained on captured held takes (held-mean decomposition, no
// truth), then removal with and without the low-pass after it, synthesis and retargeting under
// the same --model as H, and the errors that name what is wrong.
TEST(DynamicsCli, ModalTrainRemoveSynthesizeRetarget) {
  const TempDir& takes = Takes();
  TempDir dir;
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("dynamics train-modal --takes " + takes.Join("p7") + " " +
                               takes.Join("p9") + " --out " + dir.Join("modal.bin") + " --json"),
                       &out),
            0)
      << out;
  const auto fit = nlohmann::json::parse(out.substr(out.find('{')));
  EXPECT_EQ(fit["validation"], "leave one take out") << out;
  EXPECT_GT(fit["training_frames"].get<long>(), 0);
  const double residual = fit["validation_residual"].get<double>();
  EXPECT_GT(residual, 0.0);
  EXPECT_EQ(fit["ridge_rule"], "minimum");
  // The one-standard-error rule never picks a smaller ridge; an unknown rule is refused by name.
  ASSERT_EQ(RunCommand(Facedyn("dynamics train-modal --takes " + takes.Join("p7") + " " +
                               takes.Join("p9") + " --ridge-rule one-standard-error --out " +
                               dir.Join("modal_se.bin") + " --json"),
                       &out),
            0)
      << out;
  const auto fit_se = nlohmann::json::parse(out.substr(out.find('{')));
  EXPECT_EQ(fit_se["ridge_rule"], "one-standard-error");
  EXPECT_GE(fit_se["chosen_ridge"].get<double>(), fit["chosen_ridge"].get<double>());
  EXPECT_EQ(fit_se["validation_standard_error"].size(), fit_se["ridge_tried"].size());
  EXPECT_NE(RunCommand(Facedyn("dynamics train-modal --takes " + takes.Join("p7") +
                               " --ridge-rule median --out " + dir.Join("m3.bin")),
                       &out),
            0);
  EXPECT_THAT(out, HasSubstr("median"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("m3.bin")));

  ASSERT_EQ(RunCommand(Facedyn("dynamics remove --take " + takes.Join("p8") + " --model " +
                               dir.Join("modal.bin") + " --out " + dir.Join("removed")),
                       &out),
            0)
      << out;
  ASSERT_EQ(RunCommand(Facedyn("dynamics remove --take " + takes.Join("p8") + " --model " +
                               dir.Join("modal.bin") + " --lowpass-after --json --out " +
                               dir.Join("filtered")),
                       &out),
            0)
      << out;
  const auto filtered = nlohmann::json::parse(out.substr(out.find('{')));
  // Never below the plain low-pass's rule (8 Hz / 3).
  EXPECT_GE(filtered["lowpass_hz"].get<double>(), 8.0 / 3 - 1e-9) << out;
  // 8 Hz lies between the training takes' 7 and 9 Hz: removal must take away most of the offset.
  for (const char* removed : {"removed", "filtered"}) {
    ASSERT_EQ(RunCommand(Facedyn("dynamics eval --pred " + dir.Join(removed) + " --truth " +
                                 takes.Join("p8") + " --input " + takes.Join("p8") + " --json"),
                         &out),
              0)
        << out;
    const auto evaluation = nlohmann::json::parse(out.substr(out.find('{')));
    const double predicted = evaluation["reports"]["prediction"]["face"]["mean_mm"].get<double>();
    const double none = evaluation["reports"]["no_removal"]["face"]["mean_mm"].get<double>();
    EXPECT_LT(predicted, 0.5 * none) << removed << ": " << out;
  }

  ASSERT_EQ(RunCommand(Facedyn("dynamics synthesize --take " + dir.Join("removed") + " --motion " +
                               takes.Join("p9") + " --model " + dir.Join("modal.bin") + " --out " +
                               dir.Join("synth")),
                       &out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(dir.Join("synth/dynamic_offset.pc2")));
  ASSERT_EQ(RunCommand(Facedyn("dynamics retarget --source " + takes.Join("p9") + " --model " +
                               dir.Join("modal.bin") + " --expression smile --out " +
                               dir.Join("retarget")),
                       &out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(dir.Join("retarget/take.json")));

  // --lowpass-after belongs to the modal model; a truncated model file is named.
  ASSERT_EQ(RunCommand(Facedyn("dynamics train-removal --takes " + takes.Join("p7") +
                               " --targets exact --epochs 1 --batch 4000 --out " +
                               dir.Join("F.pt")),
                       &out),
            0)
      << out;
  EXPECT_EQ(RunCommand(Facedyn("dynamics remove --take " + takes.Join("p8") + " --model " +
                               dir.Join("F.pt") + " --lowpass-after --out " + dir.Join("bad")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("--lowpass-after needs a modal model"));
  {
    std::ifstream in(dir.Join("modal.bin"), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(dir.Join("cut.bin"), std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  EXPECT_EQ(RunCommand(Facedyn("dynamics remove --take " + takes.Join("p8") + " --model " +
                               dir.Join("cut.bin") + " --out " + dir.Join("bad")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("cut.bin: truncated"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("bad")));
  // A take without a held part cannot be decomposed by its held mean, and train-modal says so.
  EXPECT_EQ(RunCommand(Facedyn("dynamics train-modal --takes " + dir.Join("missing") + " --out " +
                               dir.Join("m2.bin")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("missing"));
}

TEST(DynamicsCli, PlatformSynchronousQuasistaticAndTargets) {
  const TempDir& takes = Takes();
  TempDir dir;
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("dynamics quasistatic --take " + takes.Join("p8") +
                               " --method platform-synchronous --out " + dir.Join("q")),
                       &out),
            0)
      << out;
  const auto take_json = nlohmann::json::parse(testing::ReadBytes(dir.Join("q/take.json")));
  EXPECT_EQ(take_json["metadata"]["quasistatic_method"], "platform-synchronous") << take_json;
  EXPECT_EQ(take_json["metadata"]["quasistatic_platform_hz"], 8.0) << take_json;
  ASSERT_EQ(RunCommand(Facedyn("dynamics train-removal --takes " + takes.Join("p7") + " " +
                               takes.Join("p9") +
                               " --targets platform-synchronous --epochs 1 --batch 4000 --out " +
                               dir.Join("F.pt")),
                       &out),
            0)
      << out;
  EXPECT_TRUE(std::filesystem::exists(dir.Join("F.pt")));
  // A take without a platform frequency (a walk) is refused by name, and nothing is written.
  ASSERT_EQ(RunCommand(Facedyn("sim perform --expression neutral --motion walk --seconds 0.5 "
                               "--out " + dir.Join("walk")),
                       &out),
            0)
      << out;
  EXPECT_EQ(RunCommand(Facedyn("dynamics quasistatic --take " + dir.Join("walk") +
                               " --method platform-synchronous --out " + dir.Join("q2")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("platform_hz"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("q2/take.json")));
  // ... unless the frequency is given.
  EXPECT_EQ(RunCommand(Facedyn("dynamics quasistatic --take " + dir.Join("walk") +
                               " --method platform-synchronous --platform-hz 2 --out " +
                               dir.Join("q3")),
                       &out),
            0)
      << out;
  // A trend for a changing expression; a degree out of range is refused by name.
  EXPECT_EQ(RunCommand(Facedyn("dynamics quasistatic --take " + dir.Join("walk") +
                               " --method platform-synchronous --platform-hz 2 --trend-degree 2 "
                               "--min-periods 2 --out " + dir.Join("q4")),
                       &out),
            0)
      << out;
  EXPECT_EQ(RunCommand(Facedyn("dynamics quasistatic --take " + dir.Join("walk") +
                               " --method platform-synchronous --platform-hz 2 --trend-degree 7 "
                               "--out " + dir.Join("q5")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("--trend-degree"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("q5/take.json")));
}

TEST(DynamicsCli, BadArgumentsNameTheField) {
  const TempDir& takes = Takes();
  TempDir dir;
  std::string out;
  EXPECT_EQ(RunCommand(Facedyn("dynamics train-removal --takes " + takes.Join("p7") +
                               " --epochs 0 --out " + dir.Join("F.pt")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("epochs"));
  EXPECT_EQ(RunCommand(Facedyn("dynamics train-removal --takes " + takes.Join("p7") +
                               " --target-trend-degree 9 --out " + dir.Join("F.pt")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("target_trend_degree"));
  EXPECT_EQ(RunCommand(Facedyn("dynamics train-removal --takes " + takes.Join("p7") +
                               " --targets magic --out " + dir.Join("F.pt")),
                       &out),
            2);
  EXPECT_EQ(RunCommand(Facedyn("dynamics train-removal --takes " + dir.Join("missing") + " --out " +
                               dir.Join("F.pt")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("missing"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("F.pt")));
  // A dynamic take is not decomposed: train-synthesis says what to do.
  EXPECT_EQ(RunCommand(Facedyn("dynamics train-synthesis --takes " + takes.Join("p7") +
                               " --epochs 1 --out " + dir.Join("H.pt")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("not quasistatic"));
}

}  // namespace
}  // namespace facedyn
