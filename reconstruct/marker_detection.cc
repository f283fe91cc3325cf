#include "reconstruct/marker_detection.h"

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <thread>

namespace facedyn::reconstruct {
namespace {

constexpr double kInvSqrt2Pi = 0.3989422804014327;

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

// Semi-axes of the ellipse |L d| = 1 are 1 / singular values of L.
double SemiMajorAxis(const DiskParameters& p) {
  const double a = p[2] * p[2], b = p[2] * p[3], c = p[3] * p[3] + p[4] * p[4];  // L^T L
  const double mean = 0.5 * (a + c), spread = std::sqrt(0.25 * (a - c) * (a - c) + b * b);
  return 1.0 / std::sqrt(std::max(1e-12, mean - spread));
}
double EquivalentRadius(const DiskParameters& p) { return 1.0 / std::sqrt(std::abs(p[2] * p[4])); }

struct FitResult {
  DiskParameters p{};
  bool converged = false;
  double sigma = 0.0;            // robust residual sigma
  double inlier_fraction = 0.0;  // mean Tukey weight
};

// Levenberg-Marquardt with IRLS (Tukey) on the window pixels of `image` (CV_32F).
FitResult FitDisk(const cv::Mat& image, DiskParameters p, double max_radius, int max_iterations,
                  bool fix_shape = false, bool robust_from_start = false) {
  FitResult result;
  double lambda = 1e-3;
  std::vector<double> residuals, weights;
  std::vector<std::array<double, kDiskParameterCount>> gradients;
  std::vector<Eigen::Vector2i> pixels;
  double sigma = -1.0;
  auto gather = [&](const DiskParameters& q) {
    pixels.clear();
    // The dot plus three blur widths and a margin, at most 1.5 max radii (a diverging shape
    // must not grow the window without bound).
    const int half = static_cast<int>(
        std::ceil(std::min(SemiMajorAxis(q) * (1.0 + 3.0 * q[5]), 1.5 * max_radius) + 2.0));
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
    const double floor = 0.5 + 0.04 * std::abs(p[6]);
    if (iteration >= 2 || !robust_from_start) {
      std::vector<double> absolute(residuals.size());
      for (size_t i = 0; i < residuals.size(); ++i) absolute[i] = std::abs(residuals[i]);
      sigma = std::max(floor, 1.4826 * Median(absolute));
    } else {
      sigma = std::max(floor, 0.25 * std::abs(p[6]) / 4.685);
    }
    const double tukey_c = iteration >= 2 || robust_from_start ? 4.685 * sigma : -1.0;
    const double cost = evaluate(p, true, tukey_c);
    constexpr int kN = kDiskParameterCount;
    Eigen::Matrix<double, kN, kN> jtj = Eigen::Matrix<double, kN, kN>::Zero();
    Eigen::Matrix<double, kN, 1> jtr = Eigen::Matrix<double, kN, 1>::Zero();
    for (size_t i = 0; i < pixels.size(); ++i) {
      if (fix_shape) gradients[i][2] = gradients[i][3] = gradients[i][4] = gradients[i][5] = 0.0;
      const Eigen::Map<const Eigen::Matrix<double, kN, 1>> g(gradients[i].data());
      jtj.noalias() += weights[i] * g * g.transpose();
      jtr.noalias() += weights[i] * g * residuals[i];
    }
    if (fix_shape) jtj(2, 2) = jtj(3, 3) = jtj(4, 4) = jtj(5, 5) = 1.0;
    bool improved = false;
    Eigen::Matrix<double, kN, 1> step;
    for (int attempt = 0; attempt < 8 && !improved; ++attempt) {
      Eigen::Matrix<double, kN, kN> a = jtj;
      a.diagonal() += lambda * jtj.diagonal().cwiseMax(1e-9);
      step = a.ldlt().solve(jtr);
      if (!std::isfinite(step.sum())) break;
      DiskParameters q = p;
      for (int k = 0; k < kN; ++k) q[k] += step[k];
      q[2] = std::max(q[2], 1.0 / max_radius);
      q[4] = std::max(q[4], 1.0 / max_radius);
      q[5] = std::clamp(q[5], 0.02, 1.0);
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
    if (last_center_step < 2e-3 && iteration >= 3) {
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
  evaluate(p, false, 4.685 * std::max(result.sigma, 0.5 + 0.04 * std::abs(p[6])));
  double weight_sum = 0.0;
  for (double w : weights) weight_sum += w;
  result.inlier_fraction = pixels.empty() ? 0.0 : weight_sum / pixels.size();
  result.p = p;
  return result;
}

}  // namespace

DiskParameters FitBlurredDisk(const cv::Mat& gray, const DiskParameters& initial, bool fix_shape,
                              int max_iterations, double* inlier_fraction, bool robust_from_start) {
  cv::Mat image;
  gray.convertTo(image, CV_32F);
  const FitResult fit =
      FitDisk(image, initial, 100.0, max_iterations, fix_shape, robust_from_start);
  if (inlier_fraction) *inlier_fraction = fit.inlier_fraction;
  return fit.p;
}

double BlurredDiskIntensity(const DiskParameters& p, double x, double y,
                            std::array<double, kDiskParameterCount>* gradient) {
  const double dx = x - p[0], dy = y - p[1];
  const double l11 = p[2], l12 = p[3], l22 = p[4], w = p[5];
  const double u0 = l11 * dx + l12 * dy, u1 = l22 * dy;
  const double rho = std::sqrt(u0 * u0 + u1 * u1);
  const double t = (1.0 - rho) / w;
  // Beyond 8.5 blur widths Phi is 0 or 1 and its density below 1e-15 of its peak in double
  // precision: skip erfc and exp there (most of a window is far from the edge).
  if (std::abs(t) > 8.5) {
    if (gradient) {
      gradient->fill(0.0);
      (*gradient)[6] = t > 0 ? 1.0 : 0.0;
      (*gradient)[7] = 1.0;
    }
    return p[7] + (t > 0 ? p[6] : 0.0);
  }
  const double phi = 0.5 * std::erfc(-t / std::sqrt(2.0));
  if (gradient) {
    const double a = p[6];
    const double density = kInvSqrt2Pi * std::exp(-0.5 * t * t);
    // dI/drho = -a density / w; drho/du = u / rho (0 at the centre, where the model is flat).
    const double g = rho > 1e-12 ? -a * density / (w * rho) : 0.0;
    (*gradient)[0] = g * (-l11 * u0);             // du/dx0 = -(l11, 0)
    (*gradient)[1] = g * (-l12 * u0 - l22 * u1);  // du/dy0 = -(l12, l22)
    (*gradient)[2] = g * (dx * u0);               // du/dl11 = (dx, 0)
    (*gradient)[3] = g * (dy * u0);               // du/dl12 = (dy, 0)
    (*gradient)[4] = g * (dy * u1);               // du/dl22 = (0, dy)
    (*gradient)[5] = a * density * (-t / w);
    (*gradient)[6] = phi;
    (*gradient)[7] = 1.0;
  }
  return p[7] + p[6] * phi;
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
    const DiskParameters p = {double(c.x), double(c.y), 1.0 / r0, 0.0, 1.0 / r0, 1.0 / r0, a0, b0};
    const FitResult fit = FitDisk(image, p, max_radius, options.max_iterations);
    const double contrast = options.polarity == MarkerPolarity::kDark ? -fit.p[6] : fit.p[6];
    if (!fit.converged ||
        (Eigen::Vector2d(fit.p[0] - c.x, fit.p[1] - c.y)).norm() > 2.0 * r0 + 2.0) {
      ++summary.rejected_fit;
      continue;
    }
    const double fitted_radius = EquivalentRadius(fit.p);
    if (2.0 * fitted_radius < options.min_diameter_px ||
        2.0 * fitted_radius > options.max_diameter_px) {
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
    detection.radius_px = fitted_radius;
    detection.edge_width_px = fit.p[5] * fitted_radius;
    detection.contrast = contrast;
    detection.residual_rms = fit.sigma;
    detection.quality = fit.inlier_fraction * contrast / (contrast + 3.0 * fit.sigma);
    detection.inlier_fraction = fit.inlier_fraction;
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
    std::vector<double> radii, l11, l12, l22, widths;
    for (size_t n = 0; n < k; ++n) {
      const MarkerDetection& other = detections[nearest[n].second];
      radii.push_back(other.radius_px);
      l11.push_back(other.fit[2]);
      l12.push_back(other.fit[3]);
      l22.push_back(other.fit[4]);
      widths.push_back(other.fit[5]);
    }
    std::sort(radii.begin(), radii.end());
    const double reference_radius = radii[(3 * radii.size()) / 4];
    // Only dots that are smaller than their neighbours AND leave part of their window
    // unexplained are suspects (a clean foreshortened dot is explained well).
    if (detections[i].radius_px >= 0.9 * reference_radius ||
        detections[i].inlier_fraction >= 0.95) {
      continue;
    }
    // The neighbours' shape (they face about the same way), scaled to the reference radius.
    DiskParameters shape = detections[i].fit;
    shape[2] = Median(l11);
    shape[3] = Median(l12);
    shape[4] = Median(l22);
    const double scale = EquivalentRadius(shape) / reference_radius;
    shape[2] *= scale;
    shape[3] *= scale;
    shape[4] *= scale;
    shape[5] = Median(widths);
    // The shrunken fit hugs the visible part, so the true centre lies about
    // (reference - fitted radius) away in an unknown direction: start there in 8 directions
    // (and in place) and keep the fit that explains the most pixels.
    FitResult fit;
    fit.inlier_fraction = -1.0;
    const double offset = reference_radius - detections[i].radius_px;
    for (int direction = -1; direction < 8; ++direction) {
      DiskParameters p = shape;
      if (direction >= 0) {
        p[0] += offset * std::cos(M_PI / 4 * direction);
        p[1] += offset * std::sin(M_PI / 4 * direction);
      }
      const FitResult candidate = FitDisk(image, p, max_radius, options.max_iterations, true, true);
      if (candidate.converged && candidate.inlier_fraction > fit.inlier_fraction) fit = candidate;
    }
    const double contrast = options.polarity == MarkerPolarity::kDark ? -fit.p[6] : fit.p[6];
    // Keep the refit when it explains the window about as well as the free fit (within 5% of
    // its pixels) while agreeing with the neighbours' shape: a free ellipse can take the shape
    // of a dot's visible part, and the neighbours are the evidence that decides. A dot that is
    // merely seen at an angle shares its neighbours' shape and is not refitted at all.
    if (!fit.converged || contrast < options.min_contrast ||
        fit.inlier_fraction < detections[i].inlier_fraction - 0.05 ||
        (Eigen::Vector2d(fit.p[0], fit.p[1]) - detections[i].center_px).norm() > reference_radius) {
      continue;
    }
    MarkerDetection& d = refitted[i];
    d.fit = fit.p;
    d.center_px = {fit.p[0], fit.p[1]};
    d.radius_px = EquivalentRadius(fit.p);
    d.edge_width_px = fit.p[5] * d.radius_px;
    d.contrast = contrast;
    d.residual_rms = fit.sigma;
    d.quality = fit.inlier_fraction * contrast / (contrast + 3.0 * fit.sigma);
    d.inlier_fraction = fit.inlier_fraction;
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
  std::sort(
      detections.begin(), detections.end(),
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

std::vector<StatusOr<std::vector<MarkerDetection>>> DetectMarkersInImages(
    const std::vector<cv::Mat>& images, const MarkerDetectionOptions& options, int threads) {
  std::vector<StatusOr<std::vector<MarkerDetection>>> results(
      images.size(), StatusOr<std::vector<MarkerDetection>>(InternalError("not run")));
  if (threads <= 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = std::min<int>(threads, static_cast<int>(images.size()));
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i = next++; i < images.size(); i = next++) {
      results[i] = images[i].empty()
                       ? StatusOr<std::vector<MarkerDetection>>(std::vector<MarkerDetection>())
                       : DetectMarkers(images[i], options);
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& thread : pool) thread.join();
  return results;
}

}  // namespace facedyn::reconstruct
