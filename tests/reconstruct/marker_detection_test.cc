#include "reconstruct/marker_detection.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "reconstruct/synthetic_views.h"
#include "tests/support/test_support.h"

namespace facedyn::reconstruct {
namespace {

TEST(BlurredDiskIntensity, GradientMatchesFiniteDifferences) {
  // An ellipse with semi-axes about 4 and 3 px, tilted, edge about 1.3 px.
  const DiskParameters p = {10.3, 7.8, 0.25, 0.04, 0.33, 0.3, -80.0, 190.0};
  for (const Eigen::Vector2d& at : {Eigen::Vector2d(12.0, 9.0), Eigen::Vector2d(6.5, 7.0),
                                    Eigen::Vector2d(10.0, 12.5), Eigen::Vector2d(14.0, 3.0)}) {
    std::array<double, kDiskParameterCount> gradient;
    BlurredDiskIntensity(p, at.x(), at.y(), &gradient);
    for (int k = 0; k < kDiskParameterCount; ++k) {
      DiskParameters plus = p, minus = p;
      const double h = 1e-7 * std::max(1.0, std::abs(p[k]));
      plus[k] += h;
      minus[k] -= h;
      const double numeric = (BlurredDiskIntensity(plus, at.x(), at.y()) -
                              BlurredDiskIntensity(minus, at.x(), at.y())) /
                             (2 * h);
      EXPECT_NEAR(gradient[k], numeric, 1e-5 * std::max(1.0, std::abs(numeric)))
          << "parameter " << k << " at " << at.transpose();
    }
  }
  // Far inside the ellipse the model is b + a; far outside, b.
  EXPECT_NEAR(BlurredDiskIntensity(p, 10.3, 7.8), 110.0, 0.1);
  EXPECT_NEAR(BlurredDiskIntensity(p, 30.0, 30.0), 190.0, 1e-9);
}

struct DotImage {
  cv::Mat image;
  std::vector<Eigen::Vector2d> centers;
};

// A grid of dark dots with sub-pixel centres on a mildly textured background.
DotImage MakeDots(double radius_px, double blur_px, double noise, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.5, 0.5);
  DotImage dots;
  std::vector<std::vector<Eigen::Vector2d>> polygons;
  for (int row = 0; row < 6; ++row) {
    for (int col = 0; col < 8; ++col) {
      const Eigen::Vector2d c(30.0 + 35.0 * col + jitter(rng), 30.0 + 35.0 * row + jitter(rng));
      dots.centers.push_back(c);
      polygons.push_back(CircleOutline(c, radius_px, 64));
    }
  }
  dots.image = RenderPolygons(320, 240, polygons, 190, 60, 8);
  // Skin-like low-frequency shading.
  for (int y = 0; y < dots.image.rows; ++y) {
    for (int x = 0; x < dots.image.cols; ++x) {
      auto& value = dots.image.at<unsigned char>(y, x);
      value = cv::saturate_cast<unsigned char>(value + 10.0 * std::sin(0.02 * x + 0.015 * y));
    }
  }
  if (blur_px > 0) cv::GaussianBlur(dots.image, dots.image, cv::Size(0, 0), blur_px);
  AddImageNoise(noise, &rng, &dots.image);
  return dots;
}

// Nearest detection to each true centre (or nullptr).
std::vector<const MarkerDetection*> Match(const DotImage& dots,
                                          const std::vector<MarkerDetection>& detections) {
  std::vector<const MarkerDetection*> matched;
  for (const Eigen::Vector2d& c : dots.centers) {
    const MarkerDetection* best = nullptr;
    for (const MarkerDetection& d : detections) {
      if ((d.center_px - c).norm() < 3.0 &&
          (!best || (d.center_px - c).norm() < (best->center_px - c).norm())) {
        best = &d;
      }
    }
    matched.push_back(best);
  }
  return matched;
}

TEST(DetectMarkers, SubPixelCentresUnderBlurAndNoise) {
  for (const auto& [blur, noise] :
       {std::pair{0.0, 2.0}, std::pair{1.0, 4.0}, std::pair{2.0, 6.0}}) {
    const DotImage dots = MakeDots(4.0, blur, noise, 3);
    MarkerDetectionOptions options;
    MarkerDetectionSummary summary;
    const auto detections = DetectMarkers(dots.image, options, &summary);
    ASSERT_TRUE(detections.ok()) << detections.status().ToString();
    EXPECT_EQ(detections->size(), dots.centers.size())
        << "blur " << blur << ": candidates " << summary.candidates << ", rejected fit "
        << summary.rejected_fit << " size " << summary.rejected_size << " contrast "
        << summary.rejected_contrast << " quality " << summary.rejected_quality << ", duplicates "
        << summary.duplicates;
    const auto matched = Match(dots, *detections);
    double sq = 0.0;
    for (size_t i = 0; i < matched.size(); ++i) {
      ASSERT_NE(matched[i], nullptr) << "dot " << i << " blur " << blur;
      sq += (matched[i]->center_px - dots.centers[i]).squaredNorm();
      EXPECT_NEAR(matched[i]->radius_px, 4.0, 0.6);
      EXPECT_GT(matched[i]->quality, 0.7);
    }
    const double rms = std::sqrt(sq / matched.size());
    std::printf("blur %.1f px noise %.0f: centre RMS %.4f px, %d candidates\n", blur, noise, rms,
                summary.candidates);
    EXPECT_LT(rms, 0.05 + 0.01 * noise) << "blur " << blur;
  }
}

TEST(DetectMarkers, PartialOcclusionBiasesLittleAndLowersQuality) {
  DotImage dots = MakeDots(5.0, 1.0, 2.0, 5);
  // A background-coloured band (an eyelash, a nose edge) hides a third of every other dot.
  for (size_t i = 0; i < dots.centers.size(); i += 2) {
    const Eigen::Vector2d c = dots.centers[i];
    cv::rectangle(dots.image, cv::Point2d(c.x() + 1.8, c.y() - 8),
                  cv::Point2d(c.x() + 9, c.y() + 8), cv::Scalar(185), cv::FILLED);
  }
  MarkerDetectionSummary summary;
  MarkerDetectionOptions options;
  options.occlusion_refit = true;
  const auto detections = DetectMarkers(dots.image, options, &summary);
  ASSERT_TRUE(detections.ok());
  // Without the refit the same dots are found, the hidden ones keep the bias of their visible
  // part, and their quality says so.
  MarkerDetectionSummary plain_summary;
  const auto plain = DetectMarkers(dots.image, MarkerDetectionOptions(), &plain_summary);
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(plain_summary.refitted_for_occlusion, 0);
  EXPECT_GT(summary.refitted_for_occlusion, 0);
  std::printf("candidates %d, rejected fit %d size %d contrast %d quality %d, duplicates %d\n",
              summary.candidates, summary.rejected_fit, summary.rejected_size,
              summary.rejected_contrast, summary.rejected_quality, summary.duplicates);
  const auto matched = Match(dots, *detections);
  double occluded_quality = 0.0, clear_quality = 0.0, worst_occluded = 0.0;
  int occluded = 0, clear = 0, within = 0;
  for (size_t i = 0; i < matched.size(); ++i) {
    if (!matched[i]) continue;
    const double error = (matched[i]->center_px - dots.centers[i]).norm();
    if (i % 2 == 0) {
      within += error < 0.4 ? 1 : 0;
      occluded_quality += matched[i]->quality;
      worst_occluded = std::max(worst_occluded, error);
      ++occluded;
    } else {
      clear_quality += matched[i]->quality;
      EXPECT_LT(error, 0.1);
      ++clear;
    }
  }
  ASSERT_EQ(clear, 24);
  ASSERT_GE(occluded, 20);  // most partly hidden dots are still found
  // A free ellipse fit takes the shape of the visible part (1-1.5 px off); the refit with the
  // neighbours' shape recovers the centre where the neighbours say the dot is too small. At
  // the edge of the grid (fewer clear neighbours) some keep the bias, but every partly hidden
  // dot carries a clearly lower quality, which triangulation uses as its weight.
  std::printf(
      "occluded: %d found, %d within 0.4 px, worst centre error %.3f px, mean quality "
      "%.2f vs %.2f\n",
      occluded, within, worst_occluded, occluded_quality / occluded, clear_quality / clear);
  EXPECT_GE(within, occluded / 2);
  EXPECT_LT(worst_occluded, 1.6);
  EXPECT_LT(occluded_quality / occluded, clear_quality / clear - 0.1);
  // The default (no refit): every clear dot found as precisely, the hidden ones found with
  // the bias of their visible part and a clearly lower quality.
  const auto plain_matched = Match(dots, *plain);
  double plain_occluded_quality = 0.0, plain_clear_quality = 0.0;
  int plain_occluded = 0, plain_clear = 0;
  for (size_t i = 0; i < plain_matched.size(); ++i) {
    if (!plain_matched[i]) continue;
    if (i % 2 == 0) {
      plain_occluded_quality += plain_matched[i]->quality;
      ++plain_occluded;
    } else {
      EXPECT_LT((plain_matched[i]->center_px - dots.centers[i]).norm(), 0.1);
      plain_clear_quality += plain_matched[i]->quality;
      ++plain_clear;
    }
  }
  EXPECT_EQ(plain_clear, 24);
  EXPECT_GE(plain_occluded, 20);
  EXPECT_LT(plain_occluded_quality / plain_occluded, plain_clear_quality / plain_clear - 0.1);
}

// Shading wider than any dot allowed (a nostril's rim, the shadow under the lip) makes
// band-pass candidates whose dark mass already fills the start's moment window: they are
// rejected unfitted, and every dot is still found.
TEST(DetectMarkers, ShadingWiderThanTheLargestDotIsRejectedWithoutAFit) {
  DotImage dots = MakeDots(4.0, 1.0, 2.0, 7);
  // Smooth dark blobs 25 grey levels deep (Gaussian, sigma 6 px) between the rows of dots.
  cv::Mat shading(dots.image.size(), CV_32F, cv::Scalar(0));
  std::vector<Eigen::Vector2d> blobs;
  for (int col = 0; col < 7; col += 2) blobs.emplace_back(47.5 + 35.0 * col, 47.5 + 35.0 * 2);
  for (int y = 0; y < shading.rows; ++y) {
    for (int x = 0; x < shading.cols; ++x) {
      for (const Eigen::Vector2d& b : blobs) {
        const double d2 = (Eigen::Vector2d(x, y) - b).squaredNorm();
        shading.at<float>(y, x) -= static_cast<float>(25.0 * std::exp(-0.5 * d2 / 36.0));
      }
    }
  }
  cv::Mat image;
  dots.image.convertTo(image, CV_32F);
  image += shading;
  image.convertTo(dots.image, CV_8U);
  const MarkerDetectionOptions options = MarkerDetectionOptionsForDiameter(8.0);
  EXPECT_DOUBLE_EQ(options.min_diameter_px, 3.2);
  EXPECT_DOUBLE_EQ(options.max_diameter_px, 12.0);
  MarkerDetectionSummary summary;
  const auto detections = DetectMarkers(dots.image, options, &summary);
  ASSERT_TRUE(detections.ok());
  EXPECT_GE(summary.rejected_size_unfitted, static_cast<int>(blobs.size()));
  const auto matched = Match(dots, *detections);
  for (size_t i = 0; i < matched.size(); ++i) EXPECT_NE(matched[i], nullptr) << "dot " << i;
  for (const MarkerDetection& d : *detections) {
    for (const Eigen::Vector2d& b : blobs) EXPECT_GT((d.center_px - b).norm(), 6.0);
  }
}

TEST(DetectMarkersInImages, SameAsOneByOneInImageOrder) {
  std::vector<cv::Mat> images;
  for (uint32_t seed = 1; seed <= 5; ++seed) images.push_back(MakeDots(4.0, 1.0, 3.0, seed).image);
  images.push_back(cv::Mat());  // a camera without a frame
  const auto all = DetectMarkersInImages(images, MarkerDetectionOptions(), 3);
  ASSERT_EQ(all.size(), images.size());
  for (size_t i = 0; i + 1 < images.size(); ++i) {
    const auto one = DetectMarkers(images[i], MarkerDetectionOptions());
    ASSERT_TRUE(all[i].ok() && one.ok());
    ASSERT_EQ(all[i]->size(), one->size());
    for (size_t k = 0; k < one->size(); ++k) {
      EXPECT_EQ((*all[i])[k].center_px, (*one)[k].center_px);
    }
  }
  ASSERT_TRUE(all.back().ok());
  EXPECT_TRUE(all.back()->empty());
}

TEST(DetectMarkers, NothingInAFlatImageAndBadInputRefused) {
  cv::Mat flat(200, 200, CV_8UC1, cv::Scalar(150));
  std::mt19937 rng(1);
  AddImageNoise(3.0, &rng, &flat);
  const auto detections = DetectMarkers(flat, MarkerDetectionOptions());
  ASSERT_TRUE(detections.ok());
  EXPECT_EQ(detections->size(), 0u);
  EXPECT_FALSE(DetectMarkers(cv::Mat(), MarkerDetectionOptions()).ok());
  MarkerDetectionOptions bad;
  bad.expected_diameter_px = 100;
  const auto refused = DetectMarkers(flat, bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("expected_diameter_px"), std::string::npos);
}

}  // namespace
}  // namespace facedyn::reconstruct
