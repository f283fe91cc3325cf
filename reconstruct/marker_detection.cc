#include "reconstruct/marker_detection.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

namespace facedyn::reconstruct {
namespace {

constexpr double kInvSqrt2Pi = 0.3989422804014327;

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

struct FitResult {
  DiskParameters p{};
  bool converged = false;
  double sigma = 0.0;            // robust residual sigma
  double inlier_fraction = 0.0;  // mean Tukey weight
};

// Levenberg-Marquardt with IRLS (Tukey) on the window pixels of `image` (CV_32F).
FitResult FitDisk(const cv::Mat& image, DiskParameters p, double max_radius,
                  int max_iterations, bool fix_shape = false, bool robust_from_start = false) {
  FitResult result;
  double lambda = 1e-3;
  std::vector<double> residuals, weights;
  std::vector<std::array<double, 6>> gradients;
  std::vector<Eigen::Vector2i> pixels;
  double sigma = -1.0;
  auto gather = [&](const DiskParameters& q) {
    pixels.clear();
    const int half = static_cast<int>(std::ceil(q[2] + 3.0 * q[3] + 3.0));
    const int cx = static_cast<int>(std::lround(q[0])), cy = static_cast<int>(std::lround(q[1]));
    for (int y = std::max(0, cy - half); y <= std::min(image.rows - 1, cy + half); ++y) {
      for (int x = std::max(0, cx - half); x <= std::min(image.cols - 1, cx + half); ++x) {
        pixels.emplace_back(x, y);
      }
    }
  };
  auto evaluate = [&](const DiskParameters& q, bool with_gradient, double tukey_c) {
    residuals.resize(pixels.size());
    weights.resize(pixels.size());
    if (with_gradient) gradients.resize(pixels.size());
    double cost = 0.0;
    for (size_t i = 0; i < pixels.size(); ++i) {
      const double observed = image.at<float>(pixels[i].y(), pixels[i].x());
      const double model = BlurredDiskIntensity(q, pixels[i].x(), pixels[i].y(),
                                                with_gradient ? &gradients[i] : nullptr);
      residuals[i] = observed - model;
      double weight = 1.0;
      if (tukey_c > 0) {
        const double u = residuals[i] / tukey_c;
        weight = std::abs(u) < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
      }
      weights[i] = weight;
      cost += weight * residuals[i] * residuals[i];
    }
    return cost;
  };
  gather(p);
  double last_center_step = 1e9;
  for (int iteration = 0; iteration < max_iterations; ++iteration) {
    // Robust scale: from the residuals, with a floor of a few percent of the contrast so the
    // model's own small misfit along the edge (a real blur is not exactly Gaussian) is never
    // mistaken for occlusion. From a good start (robust_from_start), the first two rounds use
    // a fixed scale of a quarter of the contrast, so pixels the start does not explain (the
    // hidden part of a dot) are outliers from the outset; otherwise the first two rounds are
    // plain least squares.
    evaluate(p, false, -1.0);
    const double floor = 0.5 + 0.04 * std::abs(p[4]);
    if (iteration >= 2 || !robust_from_start) {
      std::vector<double> absolute(residuals.size());
      for (size_t i = 0; i < residuals.size(); ++i) absolute[i] = std::abs(residuals[i]);
      sigma = std::max(floor, 1.4826 * Median(absolute));
    } else {
      sigma = std::max(floor, 0.25 * std::abs(p[4]) / 4.685);
    }
    const double tukey_c = iteration >= 2 || robust_from_start ? 4.685 * sigma : -1.0;
    const double cost = evaluate(p, true, tukey_c);
    Eigen::Matrix<double, 6, 6> jtj = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> jtr = Eigen::Matrix<double, 6, 1>::Zero();
    for (size_t i = 0; i < pixels.size(); ++i) {
      if (fix_shape) gradients[i][2] = gradients[i][3] = 0.0;
      const Eigen::Map<const Eigen::Matrix<double, 6, 1>> g(gradients[i].data());
      jtj.noalias() += weights[i] * g * g.transpose();
      jtr.noalias() += weights[i] * g * residuals[i];
    }
    if (fix_shape) jtj(2, 2) = jtj(3, 3) = 1.0;
    bool improved = false;
    Eigen::Matrix<double, 6, 1> step;
    for (int attempt = 0; attempt < 8 && !improved; ++attempt) {
      Eigen::Matrix<double, 6, 6> a = jtj;
      a.diagonal() += lambda * jtj.diagonal().cwiseMax(1e-9);
      step = a.ldlt().solve(jtr);
      DiskParameters q = p;
      for (int k = 0; k < 6; ++k) q[k] += step[k];
      q[2] = std::clamp(q[2], 0.5, max_radius);
      q[3] = std::clamp(q[3], 0.3, 0.5 * max_radius + 2.0);
      if (!std::isfinite(step.sum())) break;
      if (evaluate(q, false, tukey_c) < cost) {
        p = q;
        lambda = std::max(1e-7, lambda * 0.3);
        improved = true;
      } else {
        lambda *= 10.0;
      }
    }
    if (!improved) {  // at a minimum of the current (reweighted) cost
      result.converged = iteration >= 2;
      break;
    }
    gather(p);  // the window follows the centre
    last_center_step = step.head<2>().norm();
    if (last_center_step < 1e-4 && iteration >= 3) {
      result.converged = true;
      break;
    }
  }
  // Out of iterations but the centre has settled (the shape parameters may still creep).
  if (!result.converged && last_center_step < 0.01) result.converged = true;
  // Final robust statistics.
  evaluate(p, false, -1.0);
  std::vector<double> absolute(residuals.size());
  for (size_t i = 0; i < residuals.size(); ++i) absolute[i] = std::abs(residuals[i]);
  result.sigma = std::max(0.5, 1.4826 * Median(absolute));
  evaluate(p, false, 4.685 * std::max(result.sigma, 0.5 + 0.04 * std::abs(p[4])));
  double weight_sum = 0.0;
  for (double w : weights) weight_sum += w;
  result.inlier_fraction = pixels.empty() ? 0.0 : weight_sum / pixels.size();
  result.p = p;
  return result;
}

}  // namespace

DiskParameters FitBlurredDisk(const cv::Mat& gray, const DiskParameters& initial, bool fix_shape,
                              int max_iterations, double* inlier_fraction,
                              bool robust_from_start) {
  cv::Mat image;
  gray.convertTo(image, CV_32F);
  const FitResult fit =
      FitDisk(image, initial, 100.0, max_iterations, fix_shape, robust_from_start);
  if (inlier_fraction) *inlier_fraction = fit.inlier_fraction;
  return fit.p;
}

double BlurredDiskIntensity(const DiskParameters& p, double x, double y,
                            std::array<double, 6>* gradient) {
  const double dx = x - p[0], dy = y - p[1];
  const double r = std::sqrt(dx * dx + dy * dy);
  const double w = p[3];
  const double t = (p[2] - r) / w;
  const double phi = 0.5 * std::erfc(-t / std::sqrt(2.0));
  if (gradient) {
    const double density = kInvSqrt2Pi * std::exp(-0.5 * t * t);
    const double a = p[4];
    // d/dr of t is -1/w; dr/dx0 = -dx/r (0 at the centre, where the model is flat).
    const double drdx0 = r > 1e-12 ? -dx / r : 0.0;
    const double drdy0 = r > 1e-12 ? -dy / r : 0.0;
    (*gradient)[0] = a * density * (-1.0 / w) * drdx0;
    (*gradient)[1] = a * density * (-1.0 / w) * drdy0;
    (*gradient)[2] = a * density / w;
    (*gradient)[3] = a * density * (-t / w);
    (*gradient)[4] = phi;
    (*gradient)[5] = 1.0;
  }
  return p[5] + p[4] * phi;
}

Status MarkerDetectionOptions::Check() const {
  if (!(min_diameter_px >= 1.0)) return InvalidArgumentError("min_diameter_px must be >= 1");
  if (!(max_diameter_px > min_diameter_px) || max_diameter_px > 200) {
    return InvalidArgumentError("max_diameter_px must be in (min_diameter_px, 200]");
  }
  if (!(expected_diameter_px >= min_diameter_px && expected_diameter_px <= max_diameter_px)) {
    return InvalidArgumentError("expected_diameter_px must be within [min, max]_diameter_px");
  }
  if (!(min_contrast > 0)) return InvalidArgumentError("min_contrast must be > 0");
  if (!(min_quality >= 0 && min_quality < 1)) return InvalidArgumentError("min_quality in [0, 1)");
  if (max_iterations < 3) return InvalidArgumentError("max_iterations must be >= 3");
  return Status::Ok();
}

StatusOr<std::vector<MarkerDetection>> DetectMarkers(const cv::Mat& gray,
                                                     const MarkerDetectionOptions& options,
                                                     MarkerDetectionSummary* summary_out) {
  FACEDYN_RETURN_IF_ERROR(options.Check().WithContext("marker detection options"));
  if (gray.empty() || gray.type() != CV_8UC1) {
    return InvalidArgumentError("marker detection needs a non-empty 8-bit grayscale image");
  }
  MarkerDetectionSummary local;
  MarkerDetectionSummary& summary = summary_out ? *summary_out : local;
  summary = MarkerDetectionSummary();
  cv::Mat image;
  gray.convertTo(image, CV_32F);
  // Band-pass: small blur minus large blur, signed so dots are positive.
  const double sigma = std::max(0.8, 0.5 * options.expected_diameter_px / std::sqrt(2.0));
  cv::Mat small, large;
  cv::GaussianBlur(image, small, cv::Size(0, 0), sigma);
  cv::GaussianBlur(image, large, cv::Size(0, 0), 2.0 * sigma);
  cv::Mat response = options.polarity == MarkerPolarity::kDark ? large - small : small - large;
  // Local maxima over a neighbourhood of the smallest dot, above a fraction of min_contrast
  // (the band-pass response of a dot of contrast c is about c/4 at the matched scale).
  const int radius = std::max(1, static_cast<int>(std::floor(0.5 * options.min_diameter_px)));
  cv::Mat dilated;
  cv::dilate(response, dilated,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * radius + 1, 2 * radius + 1)));
  const float threshold = static_cast<float>(0.15 * options.min_contrast);
  std::vector<cv::Point> candidates;
  for (int y = 1; y < response.rows - 1; ++y) {
    const float* r = response.ptr<float>(y);
    const float* d = dilated.ptr<float>(y);
    for (int x = 1; x < response.cols - 1; ++x) {
      if (r[x] > threshold && r[x] >= d[x]) candidates.emplace_back(x, y);
    }
  }
  summary.candidates = static_cast<int>(candidates.size());

  std::vector<MarkerDetection> detections;
  const double max_radius = 0.5 * options.max_diameter_px;
  for (const cv::Point& c : candidates) {
    const double r0 = 0.5 * options.expected_diameter_px;
    // Initial background and amplitude from the window border and the centre.
    const int half = static_cast<int>(std::ceil(2.0 * r0 + 2.0));
    std::vector<double> border;
    for (int k = -half; k <= half; ++k) {
      for (const cv::Point& q : {cv::Point(c.x + k, c.y - half), cv::Point(c.x + k, c.y + half),
                                 cv::Point(c.x - half, c.y + k), cv::Point(c.x + half, c.y + k)}) {
        if (q.x >= 0 && q.y >= 0 && q.x < image.cols && q.y < image.rows) {
          border.push_back(image.at<float>(q));
        }
      }
    }
    const double b0 = Median(border);
    const double a0 = small.at<float>(c) - b0;
    DiskParameters p = {double(c.x), double(c.y), r0, 1.0, a0, b0};
    const FitResult fit = FitDisk(image, p, max_radius, options.max_iterations);
    const double contrast = options.polarity == MarkerPolarity::kDark ? -fit.p[4] : fit.p[4];
    if (!fit.converged || (Eigen::Vector2d(fit.p[0] - c.x, fit.p[1] - c.y)).norm() > 2.0 * r0 + 2.0) {
      ++summary.rejected_fit;
      continue;
    }
    if (2.0 * fit.p[2] < options.min_diameter_px || 2.0 * fit.p[2] > options.max_diameter_px) {
      ++summary.rejected_size;
      continue;
    }
    if (contrast < options.min_contrast) {
      ++summary.rejected_contrast;
      continue;
    }
    MarkerDetection detection;
    detection.fit = fit.p;
    detection.center_px = {fit.p[0], fit.p[1]};
    detection.radius_px = fit.p[2];
    detection.edge_width_px = fit.p[3];
    detection.contrast = contrast;
    detection.residual_rms = fit.sigma;
    detection.quality = fit.inlier_fraction * contrast / (contrast + 3.0 * fit.sigma);
    detections.push_back(detection);
  }
  // Occlusion: a partly hidden dot is fitted best by a smaller disk shifted into its visible
  // part. Occlusion can only shrink a dot's apparent radius, so a dot clearly smaller than its
  // neighbours (the 75th percentile of the radii of its 8 nearest) is refitted with their radius
  // and edge width held: the hidden pixels then become outliers instead of moving the centre.
  std::vector<MarkerDetection> refitted = detections;
  for (size_t i = 0; i < detections.size(); ++i) {
    std::vector<std::pair<double, size_t>> nearest;
    for (size_t j = 0; j < detections.size(); ++j) {
      if (j != i) {
        nearest.emplace_back((detections[j].center_px - detections[i].center_px).norm(), j);
      }
    }
    if (nearest.size() < 3) continue;
    const size_t k = std::min<size_t>(8, nearest.size());
    std::partial_sort(nearest.begin(), nearest.begin() + k, nearest.end());
    std::vector<double> radii, widths;
    for (size_t n = 0; n < k; ++n) {
      radii.push_back(detections[nearest[n].second].radius_px);
      widths.push_back(detections[nearest[n].second].edge_width_px);
    }
    std::sort(radii.begin(), radii.end());
    const double reference_radius = radii[(3 * radii.size()) / 4];
    if (detections[i].radius_px >= 0.9 * reference_radius) continue;
    // The shrunken fit hugs the visible part, so the true centre lies about
    // (reference - fitted radius) away in an unknown direction: start there in 8 directions
    // (and in place) and keep the fit that explains the most pixels.
    FitResult fit;
    fit.inlier_fraction = -1.0;
    const double offset = reference_radius - detections[i].radius_px;
    for (int direction = -1; direction < 8; ++direction) {
      DiskParameters p = detections[i].fit;
      if (direction >= 0) {
        p[0] += offset * std::cos(M_PI / 4 * direction);
        p[1] += offset * std::sin(M_PI / 4 * direction);
      }
      p[2] = reference_radius;
      p[3] = Median(widths);
      const FitResult candidate = FitDisk(image, p, max_radius, options.max_iterations, true, true);
      if (candidate.converged && candidate.inlier_fraction > fit.inlier_fraction) fit = candidate;
    }
    const double contrast = options.polarity == MarkerPolarity::kDark ? -fit.p[4] : fit.p[4];
    if (!fit.converged || contrast < options.min_contrast ||
        (Eigen::Vector2d(fit.p[0], fit.p[1]) - detections[i].center_px).norm() > reference_radius) {
      continue;
    }
    MarkerDetection& d = refitted[i];
    d.fit = fit.p;
    d.center_px = {fit.p[0], fit.p[1]};
    d.radius_px = fit.p[2];
    d.edge_width_px = fit.p[3];
    d.contrast = contrast;
    d.residual_rms = fit.sigma;
    d.quality = fit.inlier_fraction * contrast / (contrast + 3.0 * fit.sigma);
    d.refit_for_occlusion = true;
  }
  detections.clear();
  for (const MarkerDetection& d : refitted) {
    if (d.quality < options.min_quality) {
      ++summary.rejected_quality;
    } else {
      detections.push_back(d);
    }
  }
  // Several candidates can converge on one dot: keep the best within a radius.
  std::sort(detections.begin(), detections.end(),
            [](const MarkerDetection& a, const MarkerDetection& b) { return a.quality > b.quality; });
  std::vector<MarkerDetection> unique;
  for (const MarkerDetection& d : detections) {
    bool duplicate = false;
    for (const MarkerDetection& u : unique) {
      if ((u.center_px - d.center_px).norm() < std::max(u.radius_px, d.radius_px)) {
        duplicate = true;
        break;
      }
    }
    if (duplicate) {
      ++summary.duplicates;
    } else {
      unique.push_back(d);
    }
  }
  summary.accepted = static_cast<int>(unique.size());
  return unique;
}

}  // namespace facedyn::reconstruct
