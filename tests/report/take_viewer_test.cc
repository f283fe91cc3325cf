// `facedyn view` pages (report/take_viewer.h): what they contain, the errors, and — opened in
// headless Chromium, Debian's `chromium`, with software WebGL — that they draw the takes at the
// frame asked for, colour a jiggling region of the dynamic take and not of the take with the
// jiggle removed, label the frame, and raise no JavaScript error.
#include "report/take_viewer.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "core/file_util.h"
#include "core/mesh_primitives.h"
#include "tests/support/test_support.h"

namespace facedyn::report {
namespace {

using ::testing::HasSubstr;

constexpr double kFps = 40.0;
constexpr double kJiggleHz = 10.0;  // 4 frames a period: frame 5 is a peak outwards
constexpr int kFrames = 20;

bool InJigglingRegion(const Eigen::Vector3d& p) { return std::abs(p.x()) < 25.0 && std::abs(p.y()) < 25.0; }

// A face-sized patch facing +Z whose centre jiggles along +Z by 1 mm at 10 Hz; its
// "quasistatic" channel is the patch at rest. `jiggle` false: the patch at rest, no channel
// (what a perfect removal would give).
Take PatchTake(bool jiggle) {
  Take take;
  take.info.fps = kFps;
  take.info.subject = "patch";
  take.info.expression = jiggle ? "dynamic" : "removed";
  take.info.motion = "platform";
  take.info.platform_hz = kJiggleHz;
  take.topology = MakeEllipsoidPatch(80, 100, 90, 0.7, 0.7, 24, 24);
  const int v_count = take.topology.vertex_count();
  take.positions.vertex_count = v_count;
  take.positions.positions.resize(3 * v_count, kFrames);
  PointCache rest = take.positions;
  for (int f = 0; f < kFrames; ++f) {
    Eigen::Matrix3Xd frame = take.topology.positions_mm;
    rest.Frame(f) = frame.cast<float>();
    if (jiggle) {
      for (int v = 0; v < v_count; ++v) {
        if (InJigglingRegion(frame.col(v))) frame(2, v) += std::sin(2 * M_PI * kJiggleHz * f / kFps);
      }
    }
    take.positions.Frame(f) = frame.cast<float>();
    take.time_s.push_back(7.0 + f / kFps);
    take.world_from_skull.push_back(Rigid3::Identity());
  }
  if (jiggle) take.channels["quasistatic"] = rest;
  return take;
}

std::string WritePage(const testing::TempDir& dir, ViewerColour colour = ViewerColour::kOffset) {
  ViewerOptions options;
  options.colour = colour;
  const std::string path = dir.Join("view.html");
  const auto summary = WriteTakeViewer({{"dynamic", PatchTake(true)}, {"removed", PatchTake(false)}}, options, path);
  EXPECT_TRUE(summary.ok()) << summary.status().message();
  return path;
}

// The page's data block, parsed.
nlohmann::json PageData(const std::string& path) {
  const std::string page = testing::ReadBytes(path);
  const std::string open = "<script id=\"facedyn-data\" type=\"application/json\">";
  const size_t begin = page.find(open);
  EXPECT_NE(begin, std::string::npos);
  const size_t end = page.find("</script>", begin);
  return nlohmann::json::parse(page.substr(begin + open.size(), end - begin - open.size()));
}

TEST(TakeViewer, PageIsSelfContainedAndCarriesEveryFrame) {
  testing::TempDir dir;
  const std::string path = WritePage(dir);
  const std::string page = testing::ReadBytes(path);
  EXPECT_THAT(page, HasSubstr("REVISION=\"111\""));   // three.js inlined
  EXPECT_THAT(page, HasSubstr("exports.OrbitControls"));
  EXPECT_EQ(page.find("<script src"), std::string::npos);
  EXPECT_EQ(page.find("__FACEDYN_"), std::string::npos);
  const nlohmann::json data = PageData(path);
  EXPECT_EQ(data["frames"].get<int>(), kFrames);
  EXPECT_DOUBLE_EQ(data["fps"].get<double>(), kFps);
  EXPECT_NEAR(data["time_s"][5].get<double>(), 5 / kFps, 1e-9);  // from the first frame
  ASSERT_EQ(data["takes"].size(), 2u);
  EXPECT_EQ(data["takes"][0]["label"], "dynamic");
  EXPECT_THAT(data["takes"][0]["colour_source"].get<std::string>(), HasSubstr("quasistatic channel"));
  EXPECT_THAT(data["takes"][1]["colour_source"].get<std::string>(), HasSubstr("moving average"));
  // The colour range: the jiggle's 1 mm peak along the normal, near enough (the patch is curved).
  EXPECT_GT(data["colour"]["range_mm"].get<double>(), 0.5);
  EXPECT_LE(data["colour"]["range_mm"].get<double>(), 1.0 + 1e-6);
}

TEST(TakeViewer, ErrorsNameWhatIsWrongAndWriteNothing) {
  testing::TempDir dir;
  ViewerOptions options;
  options.colour = ViewerColour::kError;
  auto written = WriteTakeViewer({{"a", PatchTake(true)}}, options, dir.Join("a.html"));
  EXPECT_THAT(written.status().message(), HasSubstr("needs a truth take"));
  Take other = PatchTake(false);
  other.topology = MakeEllipsoidPatch(80, 100, 90, 0.7, 0.7, 10, 10);
  other.positions.vertex_count = other.topology.vertex_count();
  other.positions.positions = Eigen::MatrixXf::Zero(3 * other.topology.vertex_count(), kFrames);
  other.channels.clear();
  options.truth = other;
  written = WriteTakeViewer({{"a", PatchTake(true)}}, options, dir.Join("a.html"));
  EXPECT_THAT(written.status().message(), HasSubstr("vertices"));
  EXPECT_THAT(ParseViewerColour("rainbow").status().message(), HasSubstr("'rainbow'"));
  Take slow = PatchTake(false);
  slow.info.fps = 20.0;
  slow.SetUniformTimes();
  written = WriteTakeViewer({{"a", PatchTake(true)}, {"slow", slow}}, ViewerOptions(), dir.Join("a.html"));
  EXPECT_THAT(written.status().message(), HasSubstr("fps"));
  written = WriteTakeViewer({{"a", PatchTake(true)}}, ViewerOptions(), dir.Join("no/such/dir/a.html"));
  EXPECT_FALSE(written.ok());
  ViewerOptions no_three;
  no_three.three_js_path = dir.Join("three.min.js");
  written = WriteTakeViewer({{"a", PatchTake(true)}}, no_three, dir.Join("a.html"));
  EXPECT_THAT(written.status().message(), HasSubstr("libjs-three"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("a.html")));
}

TEST(TakeViewer, TheCommandLineRefusesBadInput) {
  testing::TempDir dir;
  ASSERT_TRUE(SaveTake(PatchTake(true), dir.Join("dynamic")).ok());
  std::string out;
  const std::string facedyn = testing::FacedynExecutable() + " view " + dir.Join("dynamic");
  EXPECT_EQ(testing::RunCommand(facedyn + " --color rainbow --out " + dir.Join("v.html"), &out), 1);
  EXPECT_THAT(out, HasSubstr("'rainbow'"));
  EXPECT_EQ(testing::RunCommand(facedyn + " --color error --out " + dir.Join("v.html"), &out), 1);
  EXPECT_THAT(out, HasSubstr("error:TRUTH_TAKE"));
  EXPECT_EQ(testing::RunCommand(facedyn + " --color error:" + dir.Join("missing") + " --out " + dir.Join("v.html"), &out), 1);
  EXPECT_THAT(out, HasSubstr("missing"));
  EXPECT_FALSE(std::filesystem::exists(dir.Join("v.html")));
  EXPECT_EQ(testing::RunCommand(facedyn + " --out " + dir.Join("v.html"), &out), 0) << out;
  EXPECT_TRUE(std::filesystem::exists(dir.Join("v.html")));
}

// Chromium run on the page at ?frame=5: the DOM after the scripts ran, and a screenshot.
TEST(TakeViewer, HeadlessChromiumDrawsFrameKWithTheJiggleColouredOnlyWhereItIs) {
  if (testing::ChromiumExecutable().empty()) {
    if (testing::InCi()) FAIL() << "chromium is missing and CI=true (scripts/install-deps.sh installs it)";
    GTEST_SKIP() << "chromium not installed";
  }
  testing::TempDir dir;
  const std::string page = WritePage(dir);
  const std::string url = "'file://" + page + "?frame=5'";
  const std::string chromium = testing::HeadlessChromium(dir.Join("profile")) +
                               " --window-size=1000,600 --virtual-time-budget=15000 ";
  std::string dom;
  ASSERT_EQ(testing::RunCommand(chromium + "--dump-dom " + url + " 2>/dev/null", &dom), 0) << dom;
  const std::string open = "<pre id=\"viewer-status\">";
  const size_t begin = dom.find(open);
  ASSERT_NE(begin, std::string::npos) << dom.substr(0, 2000);
  const size_t end = dom.find("</pre>", begin);
  std::string status_text = dom.substr(begin + open.size(), end - begin - open.size());
  // --dump-dom escapes the text's HTML specials.
  for (const auto& [entity, text] : {std::pair<std::string, std::string>{"&quot;", "\""}, {"&amp;", "&"}}) {
    for (size_t at; (at = status_text.find(entity)) != std::string::npos;) status_text.replace(at, entity.size(), text);
  }
  ASSERT_FALSE(status_text.empty()) << "the viewer never reported its status";
  const nlohmann::json status = nlohmann::json::parse(status_text);
  EXPECT_EQ(status["errors"].size(), 0u) << status_text;
  ASSERT_TRUE(status["ready"].get<bool>()) << status_text;
  EXPECT_EQ(status["frame"].get<int>(), 5);
  EXPECT_THAT(status["label"].get<std::string>(), HasSubstr("frame 5 / 19"));
  EXPECT_THAT(status["label"].get<std::string>(), HasSubstr("t = 0.125 s"));

  const std::string shot = dir.Join("shot.png");
  std::string out;
  ASSERT_EQ(testing::RunCommand(chromium + "--screenshot=" + shot + " " + url, &out), 0) << out;
  const cv::Mat image = cv::imread(shot, cv::IMREAD_COLOR);
  ASSERT_FALSE(image.empty()) << out;
  // The README's screenshot is this one: FACEDYN_VIEWER_SCREENSHOT=docs/viewer.png.
  if (const char* keep = std::getenv("FACEDYN_VIEWER_SCREENSHOT")) std::filesystem::copy_file(
      shot, keep, std::filesystem::copy_options::overwrite_existing);
  ASSERT_EQ(status["boxes"].size(), 2u);
  // Per take: pixels that are drawn (not the background) and pixels that are clearly red (the
  // jiggle at its outward peak) inside the take's screen box; the box's middle half is the
  // jiggling region.
  int drawn[2] = {0, 0}, red[2] = {0, 0};
  for (int t = 0; t < 2; ++t) {
    const auto& b = status["boxes"][t];
    const double x0 = b[0].get<double>(), y0 = b[1].get<double>(), x1 = b[2].get<double>(), y1 = b[3].get<double>();
    for (int y = std::max(0, static_cast<int>(y0)); y < std::min(image.rows, static_cast<int>(y1)); ++y) {
      for (int x = std::max(0, static_cast<int>(x0)); x < std::min(image.cols, static_cast<int>(x1)); ++x) {
        const cv::Vec3b bgr = image.at<cv::Vec3b>(y, x);
        if (std::abs(bgr[0] - 0x21) + std::abs(bgr[1] - 0x1f) + std::abs(bgr[2] - 0x1d) > 30) ++drawn[t];
        if (bgr[2] > 120 && bgr[2] > bgr[1] + 60 && bgr[2] > bgr[0] + 60) ++red[t];
      }
    }
  }
  const double box_area = (status["boxes"][0][2].get<double>() - status["boxes"][0][0].get<double>()) *
                          (status["boxes"][0][3].get<double>() - status["boxes"][0][1].get<double>());
  EXPECT_GT(drawn[0], 0.3 * box_area) << "the dynamic take is not drawn";
  EXPECT_GT(drawn[1], 0.3 * box_area) << "the removed take is not drawn";
  EXPECT_GT(red[0], 0.03 * box_area) << "the jiggling region of the dynamic take is not red at its peak";
  EXPECT_LT(red[1], 0.1 * red[0]) << "the take without jiggle is coloured as if it jiggled";
}

}  // namespace
}  // namespace facedyn::report
