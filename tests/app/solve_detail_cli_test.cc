// End-to-end tests of `facedyn solve` (FDLS) and `facedyn detail` (Masquerade) as a user runs
// them: a simulated take in, weights / an upsampled take out, and bad input named.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::FacedynExecutable;
using ::facedyn::testing::RunCommand;
using ::facedyn::testing::TempDir;
using ::testing::HasSubstr;

std::string Facedyn(const std::string& args) { return FacedynExecutable() + " " + args; }

// Two short takes of the procedural face (held smile, speech) made once for the process.
const TempDir& Takes() {
  static const TempDir* dir = [] {
    auto* d = new TempDir();
    std::string out;
    EXPECT_EQ(RunCommand(Facedyn("--quiet sim perform --expression smile --motion none "
                                 "--seconds 0.25 --fps 48 --out " +
                                 d->Join("smile")),
                         &out),
              0)
        << out;
    EXPECT_EQ(RunCommand(Facedyn("--quiet sim perform --expression speech --motion none "
                                 "--seconds 0.5 --fps 48 --out " +
                                 d->Join("speech")),
                         &out),
              0)
        << out;
    return d;
  }();
  return *dir;
}

std::vector<std::string> CsvLines(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

TEST(SolveCli, TrainRunOnATakeFinetuneAndApply) {
  TempDir dir;
  std::string out;
  ASSERT_EQ(
      RunCommand(Facedyn("--quiet solve train --epochs 3 --out " + dir.Join("solver") + " --json"),
                 &out),
      0)
      << out;
  const auto trained = nlohmann::json::parse(out);
  EXPECT_EQ(trained["rig"], "procedural");
  ASSERT_TRUE(std::filesystem::exists(dir.Join("solver/solver.json")));

  const std::string take = Takes().Join("smile");
  ASSERT_EQ(RunCommand(Facedyn("--quiet solve run --take " + take + " --model " +
                               dir.Join("solver") + " --out " + dir.Join("w.csv") + " --json"),
                       &out),
            0)
      << out;
  const auto network = nlohmann::json::parse(out);
  EXPECT_EQ(network["frames"], 12);
  // The procedural puppet's markers on its own blendshape skin: a small residual even after
  // 3 epochs (the take's skin includes the tissue simulation, so not zero).
  EXPECT_LT(network["network_marker_rmse_mm"].get<double>(), 0.5);
  const auto lines = CsvLines(dir.Join("w.csv"));
  ASSERT_EQ(lines.size(), 13u);  // header + 12 frames
  EXPECT_EQ(lines[0].rfind("time_s,", 0), 0u) << lines[0];
  EXPECT_THAT(lines[0], HasSubstr("smile"));
  EXPECT_THAT(lines[0], HasSubstr("jaw_open"));
  // The CSV's JSON twin beside it, with the same channels and samples.
  EXPECT_EQ(network["weights_json"], dir.Join("w.json"));
  const auto twin = nlohmann::json::parse(::facedyn::testing::ReadBytes(dir.Join("w.json")));
  EXPECT_EQ(twin["format"], "facedyn.blendshape_weights");
  EXPECT_EQ(twin["time_s"].size(), 12u);
  ASSERT_EQ(twin["weights"].size(), 12u);
  EXPECT_EQ(twin["weights"][0].size(), twin["names"].size());
  EXPECT_EQ(
      lines[0], "time_s," + [&] {
        std::string names;
        for (const auto& name : twin["names"])
          names += (names.empty() ? "" : ",") + name.get<std::string>();
        return names;
      }());

  // Fine-tuning all channels on the marker residual only lowers it.
  ASSERT_EQ(
      RunCommand(Facedyn("--quiet solve run --take " + take + " --model " + dir.Join("solver") +
                         " --out " + dir.Join("w2.csv") + " --finetune all --json"),
                 &out),
      0)
      << out;
  const auto finetuned = nlohmann::json::parse(out);
  EXPECT_LE(finetuned["finetuned_marker_rmse_mm"].get<double>(),
            finetuned["network_marker_rmse_mm"].get<double>() + 1e-9);

  // The weights drive a character with the same channel names, from the CSV or its JSON twin.
  for (const char* weights : {"w2.csv", "w2.json"}) {
    const std::string driven = dir.Join(std::string("driven_") + weights);
    ASSERT_EQ(RunCommand(Facedyn("--quiet solve apply --weights " + dir.Join(weights) + " --out " +
                                 driven),
                         &out),
              0)
        << out;
    ASSERT_EQ(RunCommand(Facedyn("take info --json " + driven + " 2>/dev/null"), &out), 0) << out;
    EXPECT_EQ(nlohmann::json::parse(out)["frames"], 12) << weights;
  }
}

TEST(SolveCli, BadInputIsNamed) {
  TempDir dir;
  std::string out;
  ASSERT_EQ(RunCommand(Facedyn("--quiet solve train --epochs 1 --out " + dir.Join("solver")), &out),
            0)
      << out;
  EXPECT_EQ(RunCommand(Facedyn("solve train --networks-at-once -1 --out " + dir.Join("s2")), &out),
            1);
  EXPECT_THAT(out, HasSubstr("--networks-at-once >= 0"));
  const std::string take = Takes().Join("smile");
  const std::string model = " --model " + dir.Join("solver") + " --out " + dir.Join("w.csv");
  // The simulator's truth never feeds a method.
  EXPECT_EQ(
      RunCommand(Facedyn("solve run --take " + take + " --channel quasistatic" + model), &out), 1);
  EXPECT_THAT(out, HasSubstr("simulator truth"));
  EXPECT_EQ(RunCommand(Facedyn("solve run --take " + take + " --finetune nose" + model), &out), 1);
  EXPECT_THAT(out, HasSubstr("'nose' is not a channel"));
  EXPECT_EQ(RunCommand(Facedyn("solve run" + model), &out), 1);
  EXPECT_THAT(out, HasSubstr("exactly one of --markers"));
  EXPECT_EQ(RunCommand(Facedyn("solve run --take " + dir.Join("no-take") + model), &out), 1);
  EXPECT_THAT(out, HasSubstr("no-take"));
  std::ofstream(dir.Join("m.csv")) << "time_s,forehead_x\n0,1\n";
  EXPECT_EQ(RunCommand(Facedyn("solve run --markers " + dir.Join("m.csv") + model), &out), 1);
  EXPECT_THAT(out, HasSubstr("m.csv"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("w.csv")));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("w.json")));
  // A weights JSON with a sample short of weights is named with its line, and no take is written.
  std::ofstream(dir.Join("w.json"))
      << "{\"format\": \"facedyn.blendshape_weights\", \"version\": 1,\n"
         "\"names\": [\"smile\", \"jaw_open\"], \"time_s\": [0, 0.1],\n"
         "\"weights\": [[0, 0.5],\n[0.2]]}\n";
  EXPECT_EQ(RunCommand(Facedyn("solve apply --weights " + dir.Join("w.json") + " --out " +
                               dir.Join("driven")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("w.json:4"));
  EXPECT_THAT(out, HasSubstr("sample 1 has 1 weights for 2 names"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("driven")));
}

TEST(DetailCli, TrainApplyAndBadModel) {
  TempDir dir;
  std::string out;
  const std::string smile = Takes().Join("smile"), speech = Takes().Join("speech");
  ASSERT_EQ(RunCommand(Facedyn("--quiet detail train --takes " + smile + " " + speech +
                               " --frames 10 --out " + dir.Join("d.bin") + " --json"),
                       &out),
            0)
      << out;
  const auto trained = nlohmann::json::parse(out);
  EXPECT_EQ(trained["selected_frames"], 10);
  EXPECT_EQ(trained["training_frames"], 36);
  // Compressed region outputs: a smaller model from the same takes; an energy outside (0, 1]
  // is refused by name.
  ASSERT_EQ(RunCommand(
                Facedyn("--quiet detail train --takes " + smile + " " + speech +
                        " --frames 10 --output-energy 0.99 --out " + dir.Join("c.bin") + " --json"),
                &out),
            0)
      << out;
  EXPECT_LT(nlohmann::json::parse(out)["memory_bytes"].get<double>(),
            trained["memory_bytes"].get<double>());
  // Every triangle in the pose (no quadrature patches): the same takes, a larger pose table.
  EXPECT_EQ(trained["pose_cell_mm"], 2.0);
  ASSERT_EQ(
      RunCommand(Facedyn("--quiet detail train --takes " + smile + " " + speech +
                         " --frames 10 --pose-cell-mm 0 --out " + dir.Join("p.bin") + " --json"),
                 &out),
      0)
      << out;
  EXPECT_GT(nlohmann::json::parse(out)["memory_bytes"].get<double>(),
            trained["memory_bytes"].get<double>());
  EXPECT_NE(RunCommand(Facedyn("detail train --takes " + smile +
                               " --frames 10 --pose-cell-mm -1 --out " + dir.Join("n.bin")),
                       &out),
            0);
  EXPECT_THAT(out, HasSubstr("--pose-cell-mm"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("n.bin")));
  EXPECT_NE(RunCommand(Facedyn("detail train --takes " + smile +
                               " --frames 10 --output-energy 0 "
                               "--out " +
                               dir.Join("z.bin")),
                       &out),
            0);
  EXPECT_THAT(out, HasSubstr("--output-energy"));
  ASSERT_EQ(RunCommand(
                Facedyn("--quiet detail train --takes " + smile + " " + speech +
                        " --frames 10 --output-energy auto --out " + dir.Join("a.bin") + " --json"),
                &out),
            0)
      << out;
  EXPECT_EQ(nlohmann::json::parse(out)["output_energy_validation_frames"], 26);
  ASSERT_EQ(RunCommand(Facedyn("--quiet detail apply --take " + speech + " --model " +
                               dir.Join("d.bin") + " --out " + dir.Join("up") + " --json"),
                       &out),
            0)
      << out;
  EXPECT_EQ(nlohmann::json::parse(out)["frames"], 24);
  ASSERT_EQ(RunCommand(Facedyn("take info --json " + dir.Join("up") + " 2>/dev/null"), &out), 0)
      << out;
  EXPECT_EQ(nlohmann::json::parse(out)["frames"], 24);
  // Frames upsampled side by side give the same files as one thread, byte for byte.
  ASSERT_EQ(
      RunCommand(Facedyn("--quiet detail apply --take " + speech + " --model " + dir.Join("d.bin") +
                         " --out " + dir.Join("up1") + " --threads 1 --json"),
                 &out),
      0)
      << out;
  EXPECT_EQ(nlohmann::json::parse(out)["threads"], 1);
  int compared = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir.Join("up"))) {
    if (!entry.is_regular_file()) continue;
    auto read = [](const std::string& path) {
      std::ifstream in(path, std::ios::binary);
      std::stringstream buffer;
      buffer << in.rdbuf();
      return buffer.str();
    };
    const std::string name = entry.path().filename().string();
    EXPECT_EQ(read(entry.path().string()), read(dir.Join("up1/" + name))) << name;
    ++compared;
  }
  EXPECT_GE(compared, 2);
  EXPECT_NE(RunCommand(Facedyn("detail apply --take " + speech + " --model " + dir.Join("d.bin") +
                               " --out " + dir.Join("up3") + " --threads -1"),
                       &out),
            0);
  EXPECT_THAT(out, HasSubstr("--threads"));

  std::ofstream(dir.Join("bad.bin")) << "garbage";
  EXPECT_EQ(RunCommand(Facedyn("detail apply --take " + speech + " --model " + dir.Join("bad.bin") +
                               " --out " + dir.Join("up2")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("bad.bin"));
  EXPECT_EQ(RunCommand(Facedyn("detail apply --take " + speech + " --model " +
                               dir.Join("none.bin") + " --out " + dir.Join("up2")),
                       &out),
            1);
  EXPECT_THAT(out, HasSubstr("none.bin"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("up2/take.json")));
}

}  // namespace
}  // namespace facedyn
