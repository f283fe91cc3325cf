#include "sim/virtual_camera.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <thread>

#include "capture/frame_sync.h"
#include "capture/trigger.h"
#include "sim/procedural_face.h"
#include "tests/support/test_support.h"

namespace facedyn::sim {
namespace {

const FaceRig& Face() {
  static const FaceRig rig = [] {
    auto made = MakeProceduralFace(ProceduralFaceOptions());
    FACEDYN_CHECK(made.ok(), made.status().message());
    return *made;
  }();
  return rig;
}

RenderOptions Clean() {
  RenderOptions options;
  options.read_noise_dn = 0;
  options.shot_noise_gain = 0;
  options.blur_sigma_px = 0;
  return options;
}

capture::CameraModel FrontCamera(int width = 640, int height = 512, double focal = 1500) {
  capture::CameraModel camera =
      capture::CameraModel::LookAt("front", width, height, focal, Eigen::Vector3d(40, 20, 750),
                                   Eigen::Vector3d(0, -5, 60), Eigen::Vector3d::UnitY());
  camera.intrinsics[4] = -0.15;  // visible barrel distortion
  camera.intrinsics[5] = 0.05;
  camera.intrinsics[6] = 0.001;
  return camera;
}

struct MarkerStats {
  int visible = 0;
  int dark = 0;
  int occluded = 0;
  int occluded_dark = 0;
  double centroid_error_px = 0;  // mean over visible markers
  std::vector<double> errors;
};

MarkerStats MeasureMarkers(const capture::CameraModel& camera, const std::vector<uint8_t>& image,
                           const RenderWorkspace& ws, const FaceRenderer& renderer) {
  MarkerStats stats;
  const Eigen::Matrix3Xd& markers = renderer.marker_rest_positions();
  double error_sum = 0;
  for (int m = 0; m < markers.cols(); ++m) {
    Eigen::Vector2d pixel;
    if (!camera.Project(markers.col(m), &pixel) || !camera.InImage(pixel, 6)) continue;
    const int x = static_cast<int>(std::lround(pixel.x())),
              y = static_cast<int>(std::lround(pixel.y()));
    const double z = (camera.cam_from_world * Eigen::Vector3d(markers.col(m))).z();
    const bool visible = std::abs(ws.depth_mm[y * camera.width_px + x] - z) < 1.0;
    // Local skin brightness: the brightest pixel in a 9x9 window.
    int local_max = 0;
    for (int dy = -4; dy <= 4; ++dy) {
      for (int dx = -4; dx <= 4; ++dx)
        local_max = std::max<int>(local_max, image[(y + dy) * camera.width_px + x + dx]);
    }
    const bool dark = image[y * camera.width_px + x] < 0.5 * local_max;
    if (visible) {
      ++stats.visible;
      stats.dark += dark;
      double wsum = 0, cx = 0, cy = 0;
      for (int dy = -4; dy <= 4; ++dy) {
        for (int dx = -4; dx <= 4; ++dx) {
          const double w =
              std::max(0.0, 0.8 * local_max - image[(y + dy) * camera.width_px + x + dx]);
          wsum += w;
          cx += w * (x + dx);
          cy += w * (y + dy);
        }
      }
      if (wsum > 0) {
        error_sum += (Eigen::Vector2d(cx / wsum, cy / wsum) - pixel).norm();
        stats.errors.push_back((Eigen::Vector2d(cx / wsum, cy / wsum) - pixel).norm());
      }
    } else {
      ++stats.occluded;
      stats.occluded_dark += dark;
    }
  }
  stats.centroid_error_px = stats.visible > 0 ? error_sum / stats.visible : 0.0;
  return stats;
}

TEST(FaceRenderer, PaintedMarkersAppearAtTheirProjections) {
  const FaceRenderer renderer(Face(), Clean());
  const capture::CameraModel camera = FrontCamera();
  RenderWorkspace ws;
  std::vector<uint8_t> image(camera.width_px * camera.height_px);
  renderer.Render(camera, Face().neutral.positions_mm, 1, &ws, image.data());
  MarkerStats stats = MeasureMarkers(camera, image, ws, renderer);
  EXPECT_GT(stats.visible, 100);
  EXPECT_GE(stats.dark, 0.95 * stats.visible);
  // The dark-blob centroid (a crude detector, biased where shading changes fast across the
  // window, e.g. at grazing angles) sits on the projected marker centre for most markers.
  std::sort(stats.errors.begin(), stats.errors.end());
  ASSERT_GT(stats.errors.size(), 100u);
  EXPECT_LT(stats.errors[stats.errors.size() / 2], 0.15);
  EXPECT_LT(stats.errors[stats.errors.size() * 3 / 4], 0.35);
  // The face is lit: skin is far brighter than the background.
  const int centre = image[(camera.height_px / 2) * camera.width_px + camera.width_px / 2];
  EXPECT_GT(centre, 100);
  EXPECT_LT(image[0], 20);
}

TEST(FaceRenderer, SelfOcclusionHidesTheFarCheek) {
  const FaceRenderer renderer(Face(), Clean());
  // From the subject's right side (-X), looking across the face.
  const capture::CameraModel camera =
      capture::CameraModel::LookAt("side", 640, 512, 1500, Eigen::Vector3d(-650, 0, 300),
                                   Eigen::Vector3d(0, -5, 60), Eigen::Vector3d::UnitY());
  RenderWorkspace ws;
  std::vector<uint8_t> image(camera.width_px * camera.height_px);
  renderer.Render(camera, Face().neutral.positions_mm, 1, &ws, image.data());
  const MarkerStats stats = MeasureMarkers(camera, image, ws, renderer);
  EXPECT_GT(stats.occluded, 10);
  EXPECT_GT(stats.visible, 20);
  // Markers behind the nose or on the far cheek must not show through the skin in front.
  EXPECT_LE(stats.occluded_dark, 0.1 * stats.occluded);
  EXPECT_GE(stats.dark, 0.9 * stats.visible);
}

TEST(FaceRenderer, SensorNoiseIsDeterministicWithTheConfiguredSigma) {
  RenderOptions options = Clean();
  options.read_noise_dn = 3.0;
  options.background = 0.2;
  const FaceRenderer renderer(Face(), options);
  // Looking away from the face: only background.
  const capture::CameraModel camera =
      capture::CameraModel::LookAt("away", 320, 256, 400, Eigen::Vector3d(0, 0, 700),
                                   Eigen::Vector3d(0, 0, 1400), Eigen::Vector3d::UnitY());
  RenderWorkspace ws;
  std::vector<uint8_t> a(320 * 256), b(320 * 256), c(320 * 256);
  renderer.Render(camera, Face().neutral.positions_mm, 7, &ws, a.data());
  renderer.Render(camera, Face().neutral.positions_mm, 7, &ws, b.data());
  renderer.Render(camera, Face().neutral.positions_mm, 8, &ws, c.data());
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  const double mean = std::accumulate(a.begin(), a.end(), 0.0) / a.size();
  double var = 0;
  for (uint8_t v : a) var += (v - mean) * (v - mean);
  const double sigma = std::sqrt(var / a.size());
  EXPECT_NEAR(mean, 0.2 * 255, 0.3);
  EXPECT_NEAR(sigma, std::sqrt(3.0 * 3.0 + 1.0 / 12), 0.15);  // read noise plus rounding
}

std::shared_ptr<Take> StaticTake(int frames, double fps,
                                 const Eigen::Vector3d& velocity_mm_per_frame) {
  auto take = std::make_shared<Take>();
  take->info.fps = fps;
  take->topology = Face().neutral;
  take->positions.vertex_count = Face().vertex_count();
  take->positions.positions.resize(3 * Face().vertex_count(), frames);
  for (int f = 0; f < frames; ++f) {
    Eigen::Matrix3Xd p = Face().neutral.positions_mm;
    p.colwise() += f * velocity_mm_per_frame;
    take->positions.Frame(f) = p.cast<float>();
    take->world_from_skull.push_back(Rigid3::FromTranslation(f * velocity_mm_per_frame));
  }
  take->SetUniformTimes();
  return take;
}

TEST(FaceRenderer, MotionBlurAveragesOverTheExposure) {
  const capture::CameraModel camera = FrontCamera(320, 256, 750);
  auto run = [&](int samples, const Eigen::Vector3d& velocity) {
    RenderOptions options = Clean();
    options.motion_blur_samples = samples;
    auto renderer = std::make_shared<FaceRenderer>(Face(), options);
    SimCamera sim(0, camera, renderer, StaticTake(3, 100.0, velocity));
    capture::CameraSettings settings{320, 256, capture::PixelFormat::kMono8, 8000, 100.0};
    EXPECT_TRUE(sim.Configure(settings).ok());
    EXPECT_TRUE(sim.Arm().ok());
    EXPECT_TRUE(sim.OnTrigger({0, 0}).ok());
    capture::Frame frame;
    bool got = false;
    EXPECT_TRUE(sim.NextFrame(1.0, &frame, &got).ok());
    EXPECT_TRUE(got);
    return frame.pixels;
  };
  const Eigen::Vector3d still = Eigen::Vector3d::Zero(), moving(6.0, 0, 0);
  const std::vector<uint8_t> sharp_still = run(1, still), blurred_still = run(6, still);
  int differing = 0;
  for (size_t i = 0; i < sharp_still.size(); ++i)
    differing += std::abs(sharp_still[i] - blurred_still[i]) > 1;
  EXPECT_LT(differing, 10);  // no motion: the average of identical instants
  const std::vector<uint8_t> sharp = run(1, moving), blurred = run(6, moving);
  auto horizontal_gradient = [](const std::vector<uint8_t>& image) {
    double sum = 0;
    for (int y = 0; y < 256; ++y) {
      for (int x = 1; x < 320; ++x) sum += std::abs(image[y * 320 + x] - image[y * 320 + x - 1]);
    }
    return sum;
  };
  EXPECT_LT(horizontal_gradient(blurred), 0.85 * horizontal_gradient(sharp));
}

TEST(SimCamera, InjectedFaultsAreSeenByTheSyncChecker) {
  const capture::CameraModel camera = FrontCamera(64, 48, 120);
  auto renderer = std::make_shared<FaceRenderer>(Face(), Clean());
  SimCameraFaults faults;
  faults.drop_triggers = {3};
  faults.duplicate_triggers = {5};
  faults.late_triggers = {7};
  SimCamera sim(1, camera, renderer, StaticTake(12, 128.0, Eigen::Vector3d::Zero()), faults);
  ASSERT_TRUE(sim.Configure({64, 48, capture::PixelFormat::kMono8, 1000, 128.0}).ok());
  ASSERT_TRUE(sim.Arm().ok());
  capture::FrameSyncChecker checker(1000);
  std::vector<int64_t> order;
  // Triggers come from their own thread, as in a take (the camera holds at most 8 pending).
  std::thread trigger_thread([&sim] {
    for (int k = 0; k < 12; ++k) {
      EXPECT_TRUE(sim.OnTrigger({k, capture::VirtualTrigger::PulseTimeNs(k, 128.0)}).ok());
    }
    EXPECT_TRUE(sim.Disarm().ok());
  });
  capture::Frame frame;
  for (;;) {
    bool got = false;
    const Status status = sim.NextFrame(0.5, &frame, &got);
    if (status.code() == StatusCode::kAborted) break;
    ASSERT_TRUE(status.ok()) << status.message();
    if (!got) continue;
    EXPECT_EQ(frame.camera_index, 1);
    order.push_back(frame.trigger_index);
    (void)checker.Observe(frame.trigger_index, frame.timestamp_ns,
                          capture::VirtualTrigger::PulseTimeNs(frame.trigger_index, 128.0), 12);
  }
  trigger_thread.join();
  EXPECT_EQ(order, (std::vector<int64_t>{0, 1, 2, 4, 5, 5, 6, 8, 7, 9, 10, 11}));
  checker.Finish(12);
  EXPECT_EQ(checker.counts().missing, 1);
  EXPECT_EQ(checker.counts().duplicated, 1);
  EXPECT_EQ(checker.counts().out_of_order, 1);
  EXPECT_EQ(checker.counts().timestamp_mismatch, 0);
}

TEST(SimCamera, ConfigureRejectsMismatchedSettings) {
  auto renderer = std::make_shared<FaceRenderer>(Face(), Clean());
  SimCamera sim(0, FrontCamera(64, 48, 120), renderer,
                StaticTake(2, 128.0, Eigen::Vector3d::Zero()));
  EXPECT_NE(sim.Configure({65, 48, capture::PixelFormat::kMono8, 1000, 128.0})
                .message()
                .find("calibration"),
            std::string::npos);
  EXPECT_NE(sim.Configure({64, 48, capture::PixelFormat::kMono8, 1000, 96.0}).message().find("fps"),
            std::string::npos);
  EXPECT_FALSE(sim.Arm().ok());
  ASSERT_TRUE(sim.Configure({64, 48, capture::PixelFormat::kMono8, 1000, 128.0}).ok());
  ASSERT_TRUE(sim.Arm().ok());
  ASSERT_TRUE(sim.OnTrigger({5, 0}).ok());
  capture::Frame frame;
  bool got = false;
  const Status beyond = sim.NextFrame(0.5, &frame, &got);
  EXPECT_FALSE(got);
  EXPECT_NE(beyond.message().find("beyond"), std::string::npos) << beyond.message();
}

}  // namespace
}  // namespace facedyn::sim
