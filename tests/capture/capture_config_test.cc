// CAPTURE.yaml checks that protect allocations: frame sizes are capped like a frame file's.
#include "capture/capture_config.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/test_support.h"

namespace facedyn::capture {
namespace {

using ::testing::HasSubstr;

StatusOr<CaptureConfig> LoadText(const testing::TempDir& dir, const std::string& text) {
  const std::string path = dir.Join("capture.yaml");
  testing::WriteBytes(path, text);
  return LoadCaptureConfig(path);
}

std::string OpencvCapture(const std::string& size, const std::string& format = "mono8") {
  return "name: t\nfps: 30\nduration_s: 1\nexposure_us: 1000\npixel_format: " + format +
         "\ncameras: {backend: opencv, sources: [a.avi, b.avi], size_px: " + size + "}\n";
}

// Before, size_px had no upper bound: [100000, 100000] was accepted and every frame buffer
// would have been 10^10 bytes.
TEST(LoadCaptureConfig, FrameSizesBeyondTheCapsAreRefusedNamingTheCamera) {
  testing::TempDir dir;
  auto ok = LoadText(dir, OpencvCapture("[1280, 1024]"));
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->uncalibrated_sizes.size(), 2u);

  auto wide = LoadText(dir, OpencvCapture("[100000, 100000]"));
  ASSERT_FALSE(wide.ok());
  EXPECT_THAT(wide.status().message(),
              HasSubstr("cameras.size_px: camera cam0 is 100000x100000 px, outside 1..65536"));

  // Within the side cap but over 1 GiB a frame in bgr8: 65536 x 8192 x 3 = 1.5 GiB.
  auto heavy = LoadText(dir, OpencvCapture("[65536, 8192]", "bgr8"));
  ASSERT_FALSE(heavy.ok());
  EXPECT_THAT(heavy.status().message(),
              HasSubstr("camera cam0 at 65536x8192 bgr8 needs 1610612736 bytes a frame"));
}

}  // namespace
}  // namespace facedyn::capture
