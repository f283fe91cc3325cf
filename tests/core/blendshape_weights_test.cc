// Blendshape weights files (core/blendshape_weights.h): the JSON twin of the CSV, its round trip
// and its errors, and the reader that picks the layout by extension.
#include "core/blendshape_weights.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::testing::HasSubstr;

BlendshapeWeightsTrack SampleTrack() {
  BlendshapeWeightsTrack track;
  track.names = {"jawOpen", "mouthSmile_L", "eyeBlink_R"};
  track.time_s = {0.0, 1.0 / 60.0, 2.0 / 60.0, 0.05 + 1e-12};
  track.weights.resize(4, 3);
  // Values that need all of a double's digits, a tiny one and a small overshoot.
  track.weights << 0.0, 1.0 / 3.0, 0.1, 0.7071067811865476, -0.012, 1e-17, 1.02, 2.0 / 7.0,
      0.3333333333333333, 0.5, 0.25, 0.125;
  return track;
}

void WriteText(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

TEST(BlendshapeWeightsJson, RoundTripGivesBackTheSameDoubles) {
  testing::TempDir dir;
  const BlendshapeWeightsTrack track = SampleTrack();
  const std::string path = dir.Join("w.json");
  ASSERT_TRUE(WriteBlendshapeWeightsJson(path, track).ok());
  const StatusOr<BlendshapeWeightsTrack> read = ReadBlendshapeWeightsJson(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->names, track.names);
  EXPECT_EQ(read->time_s, track.time_s);  // exact, not near
  ASSERT_EQ(read->weights.rows(), 4);
  ASSERT_EQ(read->weights.cols(), 3);
  for (Eigen::Index i = 0; i < track.weights.size(); ++i)
    EXPECT_EQ(read->weights.data()[i], track.weights.data()[i]) << "entry " << i;
  // The layout the header documents, one sample per line.
  const std::string text = testing::ReadBytes(path);
  EXPECT_THAT(text, HasSubstr("\"format\": \"facedyn.blendshape_weights\""));
  EXPECT_THAT(text, HasSubstr("\"names\": [\"jawOpen\",\"mouthSmile_L\",\"eyeBlink_R\"]"));
  EXPECT_THAT(text, HasSubstr("\n  [0.0,0.3333333333333333,0.1],\n"));
  // Three header lines (the third opens "weights"), a line per sample, the closing line.
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 3 + 4 + 2);
}

TEST(BlendshapeWeightsJson, ReaderPicksTheLayoutByExtension) {
  testing::TempDir dir;
  const BlendshapeWeightsTrack track = SampleTrack();
  ASSERT_TRUE(WriteBlendshapeWeightsJson(dir.Join("w.JSON"), track).ok());
  ASSERT_TRUE(WriteBlendshapeWeightsCsv(dir.Join("w.csv"), track).ok());
  const auto from_json = ReadBlendshapeWeights(dir.Join("w.JSON"));
  const auto from_csv = ReadBlendshapeWeights(dir.Join("w.csv"));
  ASSERT_TRUE(from_json.ok()) << from_json.status().ToString();
  ASSERT_TRUE(from_csv.ok()) << from_csv.status().ToString();
  EXPECT_EQ(from_json->names, from_csv->names);
  // The CSV keeps 9 significant digits, the JSON every digit.
  EXPECT_TRUE(from_json->weights.isApprox(from_csv->weights, 1e-8));
  EXPECT_EQ(from_json->weights(0, 1), 1.0 / 3.0);
  // A CSV under a .json name is read as JSON and fails as JSON, naming the file.
  std::filesystem::copy_file(dir.Join("w.csv"), dir.Join("csv.json"));
  const auto wrong = ReadBlendshapeWeights(dir.Join("csv.json"));
  ASSERT_FALSE(wrong.ok());
  EXPECT_THAT(wrong.status().message(), HasSubstr("csv.json"));
}

TEST(BlendshapeWeightsJson, ErrorsNameTheFileAndTheField) {
  testing::TempDir dir;
  const std::string path = dir.Join("bad.json");
  const std::string head = "{\"format\": \"facedyn.blendshape_weights\", \"version\": 1,\n";
  struct Case {
    std::string text;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {"[1, 2]", "expected a JSON object"},
      {"{\"format\": \"arkit\", \"version\": 1, \"names\": [], \"time_s\": [], \"weights\": []}",
       "'arkit' is not 'facedyn.blendshape_weights'"},
      {"{\"format\": \"facedyn.blendshape_weights\", \"version\": 7, \"names\": [\"a\"], "
       "\"time_s\": [0], \"weights\": [[0]]}",
       "7 is not a version this build reads"},
      {head + "\"names\": [\"a\"], \"time_s\": [0], \"weights\": [[0]], \"fps\": 60}", "fps"},
      {head + "\"names\": [\"a\"], \"time_s\": [0]}", "weights"},
      {head + "\"names\": [\"a\", \"b\"], \"time_s\": [0, 1],\n\"weights\": [[0, 1],\n[0.5]]}",
       "sample 1 has 1 weights for 2 names"},
      {head + "\"names\": [\"a\"], \"time_s\": [0, 1], \"weights\": [[0]]}",
       "1 samples of weights for 2 times"},
      {head + "\"names\": [\"a\"], \"time_s\": [0], \"weights\": [[\"heavy\"]]}", "heavy"},
      {head + "\"names\": [\"a\"], \"time_s\": [1, 0.5], \"weights\": [[0], [1]]}",
       "not finite and after the previous one"},
      {head + "\"names\": [\"a\", \"a\"], \"time_s\": [0], \"weights\": [[0, 1]]}",
       "'a' appears twice"},
      {head + "\"names\": [], \"time_s\": [], \"weights\": []}", "no samples"},
      {head + "\"names\": [\"a\"], \"time_s\": [0], \"weights\": [[0]", "bad.json"},
  };
  for (const Case& c : cases) {
    WriteText(path, c.text);
    const auto read = ReadBlendshapeWeightsJson(path);
    ASSERT_FALSE(read.ok()) << c.text;
    EXPECT_THAT(read.status().message(), HasSubstr(c.expected)) << c.text;
    EXPECT_THAT(read.status().message(), HasSubstr("bad.json")) << c.text;
  }
  // The sample's line is named.
  WriteText(path, head +
                      "\"names\": [\"a\", \"b\"], \"time_s\": [0, 1],\n\"weights\": [[0, 1],\n"
                      "[0.5]]}");
  EXPECT_THAT(ReadBlendshapeWeightsJson(path).status().message(), HasSubstr("bad.json:4"));
}

TEST(BlendshapeWeightsJson, AnInvalidTrackIsNotWritten) {
  testing::TempDir dir;
  BlendshapeWeightsTrack track = SampleTrack();
  track.weights(2, 1) = std::nan("");
  const Status status = WriteBlendshapeWeightsJson(dir.Join("w.json"), track);
  EXPECT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("not finite"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("w.json")));
}

}  // namespace
}  // namespace facedyn
