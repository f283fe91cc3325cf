#include "reconstruct/marker_detection.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <ctime>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "core/check.h"

namespace facedyn::reconstruct {
namespace {

constexpr double kInvSqrt2Pi = 0.3989422804014327;

// The standard normal CDF Phi and its density on t in [-kPhiRange, kPhiRange], as a cubic Hermite
// interpolant of exact values and slopes at nodes kPhiStep apart. The fit evaluates Phi at every
// window pixel several times per iteration; libm's erfc and exp were half of detection's time.
// Interpolation error: h^4/384 times the largest fourth derivative of Phi, below 4e-9, for Phi;
// about 1e-6 of the peak for the density. The density returned is the interpolant's own
// derivative, so the model's gradient is exact for the model that is evaluated (the
// Levenberg-Marquardt steps and the finite-difference test see one consistent function).
constexpr double kPhiRange = 8.5;  // beyond, Phi is 0 or 1 in double precision
constexpr double kPhiStep = 1.0 / 32.0;
constexpr int kPhiNodes = static_cast<int>(2 * kPhiRange / kPhiStep) + 1;

struct PhiTable {
  std::array<double, kPhiNodes> phi{}, density{};
  PhiTable() {
    for (int k = 0; k < kPhiNodes; ++k) {
      const double t = -kPhiRange + k * kPhiStep;
      phi[k] = 0.5 * std::erfc(-t / std::sqrt(2.0));
      density[k] = kInvSqrt2Pi * std::exp(-0.5 * t * t);
    }
  }
};

const PhiTable& PhiNodes() {
  static const PhiTable table;
  return table;
}

// The upper median of *values, which it reorders (the callers' buffers are scratch).
double MedianInPlace(std::vector<double>* values) {
  if (values->empty()) return 0.0;
  const size_t mid = values->size() / 2;
  std::nth_element(values->begin(), values->begin() + mid, values->end());
  return (*values)[mid];
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
  bool abandoned = false;        // crossed the caller's bounds (see FitBounds)
  int iterations = 0;
  int evaluations = 0;  // passes over the window (residuals, or gradients and normal equations)
  long pixel_evaluations = 0;
};

// The model, four pixels at a time, with GCC's vector extension (Clang has it too): one AVX2
// register in FitDisk's x86-64-v3 variant, two SSE2 halves otherwise. It is the only
// implementation: DiskModel (one pixel, for BlurredDiskIntensity and the occlusion refit's
// start scores) evaluates it on a broadcast pixel, so the finite-difference test of
// BlurredDiskIntensity's gradient checks what the fit uses.
typedef double Lanes __attribute__((vector_size(4 * sizeof(double))));
constexpr int kLanes = 4;

// The standard normal CDF's table per interval (a cubic Hermite interpolant, PhiTable): node k
// holds (Phi, step x density) at nodes k and k + 1, so one lane's data is one 32-byte load; two
// extra nodes hold the constants beyond kPhiRange.
struct HermiteNodes {
  static constexpr int kBelow = kPhiNodes - 1, kAbove = kPhiNodes;
  std::array<std::array<double, 4>, kPhiNodes + 1> node{};
  HermiteNodes() {
    const PhiTable& table = PhiNodes();
    for (int k = 0; k + 1 < kPhiNodes; ++k) {
      node[k] = {table.phi[k], kPhiStep * table.density[k], table.phi[k + 1],
                 kPhiStep * table.density[k + 1]};
    }
    node[kBelow] = {0.0, 0.0, 0.0, 0.0};
    node[kAbove] = {1.0, 0.0, 1.0, 0.0};
  }
};

const HermiteNodes& PhiHermiteNodes() {
  static const HermiteNodes nodes;
  return nodes;
}

// (Values are passed through pointers, never returned: a 32-byte vector in a function's
// signature would depend on whether AVX is enabled, GCC's -Wpsabi.)
inline void LoadLanes(const double* from, Lanes* to) { std::memcpy(to, from, sizeof(Lanes)); }

// The model's value at four pixels (x, y) into *value; with `gradient` (8 entries) its
// gradient too.
inline void DiskModelLanes(const DiskParameters& p, const double* x, const double* y, Lanes* value,
                           Lanes* gradient) {
  Lanes dx, dy;
  LoadLanes(x, &dx);
  LoadLanes(y, &dy);
  dx -= p[0];
  dy -= p[1];
  const double l11 = p[2], l12 = p[3], l22 = p[4], w = p[5];
  const Lanes u0 = l11 * dx + l12 * dy, u1 = l22 * dy;
  Lanes rho = u0 * u0 + u1 * u1;
  for (int j = 0; j < kLanes; ++j) rho[j] = std::sqrt(rho[j]);
  const Lanes t = (1.0 - rho) / w;
  // Per lane, the interval's Hermite data in one 32-byte load (HermiteNodes); beyond kPhiRange
  // the constant 0 or 1 with no slope (s = 0 selects p0, and the density m0 / step = 0), as
  // DiskModel's branch. Selects, not branches: pixels on either side of the edge alternate.
  const HermiteNodes& nodes = PhiHermiteNodes();
  Lanes s, row[kLanes];
  for (int j = 0; j < kLanes; ++j) {
    const double u = (std::clamp(t[j], -kPhiRange, kPhiRange) + kPhiRange) / kPhiStep;
    int k = std::min(kPhiNodes - 2, static_cast<int>(u));
    double fraction = u - k;
    k = t[j] > kPhiRange ? HermiteNodes::kAbove : (t[j] < -kPhiRange ? HermiteNodes::kBelow : k);
    fraction = std::abs(t[j]) > kPhiRange ? 0.0 : fraction;
    s[j] = fraction;
    std::memcpy(&row[j], nodes.node[k].data(), sizeof(Lanes));
  }
  const Lanes p0 = {row[0][0], row[1][0], row[2][0], row[3][0]};
  const Lanes m0 = {row[0][1], row[1][1], row[2][1], row[3][1]};
  const Lanes p1 = {row[0][2], row[1][2], row[2][2], row[3][2]};
  const Lanes m1 = {row[0][3], row[1][3], row[2][3], row[3][3]};
  const Lanes s2 = s * s, s3 = s2 * s;
  const Lanes phi = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 +
                    (s3 - s2) * m1;
  if (gradient) {
    const Lanes density =
        ((6 * s2 - 6 * s) * (p0 - p1) + (3 * s2 - 4 * s + 1) * m0 + (3 * s2 - 2 * s) * m1) /
        kPhiStep;
    const double a = p[6];
    const Lanes g = rho > 1e-12 ? -a * density / (w * rho) : Lanes{};
    gradient[0] = g * (-l11 * u0);
    gradient[1] = g * (-l12 * u0 - l22 * u1);
    gradient[2] = g * (dx * u0);
    gradient[3] = g * (dy * u0);
    gradient[4] = g * (dy * u1);
    gradient[5] = a * density * (-t / w);
    gradient[6] = phi;
    gradient[7] = Lanes{} + 1.0;
  }
  *value = p[7] + p[6] * phi;
}

// The model at one pixel: its value and, when `gradient` is given, its gradient with respect
// to p (DiskModelLanes' first lane).
inline double DiskModel(const DiskParameters& p, double x, double y, double* gradient) {
  const double xs[kLanes] = {x, x, x, x}, ys[kLanes] = {y, y, y, y};
  Lanes value, lanes_gradient[kDiskParameterCount];
  DiskModelLanes(p, xs, ys, &value, gradient ? lanes_gradient : nullptr);
  for (int k = 0; gradient && k < kDiskParameterCount; ++k) gradient[k] = lanes_gradient[k][0];
  return value[0];
}

// Levenberg-Marquardt with IRLS (Tukey) on the window pixels of `image` (CV_8U: read in place,
// no per-image conversion).
//
// Cost per iteration: one pass that forms the weighted normal equations J^T W J, J^T W r
// directly (the Jacobian is never stored), and one residual-only pass per trial step. A
// rejected step therefore costs no gradients, and an accepted step's residuals are the next
// iteration's; the window's pixels are gathered again only when the window moves (the centre
// crosses a pixel or the shape grows).
//
// `bounds`: a fit whose accepted step takes its centre further than max_travel from origin, or
// its equivalent radius (from the third iteration, after the plain least-squares rounds) above
// max_equivalent_radius, or (abandon_at_width_limit, from the fourth) its edge width to the
// model's limit of one radius (a blob, not a blurred disk), is abandoned there as not
// converged. The caller rejects such a fit
// anyway, and a candidate that is no dot (skin texture, an edge) otherwise wanders for the
// whole iteration budget over a window grown to its cap: on the simulated rig's captured faces
// that was a third of the fits and most of detection's time.
struct FitBounds {
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();
  double max_travel = std::numeric_limits<double>::infinity();
  double max_equivalent_radius = std::numeric_limits<double>::infinity();
  bool abandon_at_width_limit = false;
  // The window's margin beyond the dot's reach (see gather): the 1 px hysteresis plus half a
  // pixel. A start that may be further off (the occlusion refit's displaced starts) needs more.
  double window_margin_px = 1.5;
};

// FitDisk is most of detection's time and its per-pixel arithmetic gains from AVX2 and FMA;
// GCC's function multiversioning builds it twice and picks the variant at load time from the
// CPU, so the binary still runs on any x86-64 (measured in the commit that added this).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define FACEDYN_AVX2_CLONE __attribute__((target_clones("arch=x86-64-v3", "default"), flatten))
#else
#define FACEDYN_AVX2_CLONE
#endif

FACEDYN_AVX2_CLONE
FitResult FitDisk(const cv::Mat& image, DiskParameters p, double max_radius, int max_iterations,
                  bool fix_shape = false, bool robust_from_start = false,
                  const FitBounds& bounds = FitBounds()) {
  FitResult result;
  double lambda = 1e-3;
  constexpr int kN = kDiskParameterCount;
  using Normal = Eigen::Matrix<double, kN, kN>;
  using Vector = Eigen::Matrix<double, kN, 1>;
  // The window, structure of arrays: pixel coordinates and observed values of its n pixels,
  // padded to whole groups of kLanes with copies of the last pixel, which carry weight 0 and
  // enter no statistic (everything below reads the first n).
  // Per-thread scratch kept across calls: a fit allocates nothing once its thread has fitted a
  // window as large (seven vectors allocated and grown per fit were a tenth of its time).
  struct Scratch {
    std::vector<double> xs, ys, observed, current, trial, weights, absolute;
  };
  static thread_local Scratch scratch;
  std::vector<double>& xs = scratch.xs;
  std::vector<double>& ys = scratch.ys;
  std::vector<double>& observed = scratch.observed;
  std::vector<double>& current = scratch.current;
  std::vector<double>& trial = scratch.trial;
  std::vector<double>& weights = scratch.weights;
  std::vector<double>& absolute = scratch.absolute;
  size_t n = 0;
  int window_cx = INT32_MIN, window_cy = INT32_MIN, window_half = -1;
  // A disk around the window centre: the dot's semi-major axis plus three blur widths (`reach`,
  // at most 1.5 max radii: a diverging shape must not grow the window without bound), plus the
  // margin (by default the hysteresis below, 1 px, and half a pixel). Round, not square: the
  // square's corners were a fifth of its pixels and informed only the background. Returns whether
  // the window changed.
  auto gather = [&](const DiskParameters& q) {
    const double reach =
        std::min(SemiMajorAxis(q) * (1.0 + 3.0 * q[5]), 1.5 * max_radius) + bounds.window_margin_px;
    const int half = static_cast<int>(std::ceil(reach));
    // With hysteresis: the window keeps its place while the centre stays within a pixel of the
    // window's centre, and its size unless the dot needs more or a pixel less on each side
    // (the margin covers both). Each move costs a pass over the new window.
    if (window_half >= 0 && half <= window_half && half >= window_half - 1 &&
        std::abs(q[0] - window_cx) <= 1.0 && std::abs(q[1] - window_cy) <= 1.0) {
      return false;
    }
    const int cx = static_cast<int>(std::lround(q[0])), cy = static_cast<int>(std::lround(q[1]));
    if (cx == window_cx && cy == window_cy && half == window_half) return false;
    window_cx = cx;
    window_cy = cy;
    window_half = half;
    xs.clear();
    ys.clear();
    observed.clear();
    for (int y = std::max(0, cy - half); y <= std::min(image.rows - 1, cy + half); ++y) {
      const uchar* row = image.ptr<uchar>(y);
      for (int x = std::max(0, cx - half); x <= std::min(image.cols - 1, cx + half); ++x) {
        if ((x - cx) * (x - cx) + (y - cy) * (y - cy) > reach * reach) continue;
        xs.push_back(x);
        ys.push_back(y);
        observed.push_back(row[x]);
      }
    }
    n = xs.size();
    if (n == 0) {  // a centre far outside the image: one pixel-less group
      xs.push_back(cx);
      ys.push_back(cy);
      observed.push_back(0.0);
    }
    while (xs.size() % kLanes != 0) {
      xs.push_back(xs.back());
      ys.push_back(ys.back());
      observed.push_back(observed.back());
    }
    weights.assign(xs.size(), 0.0);
    return true;
  };
  auto residuals_at = [&](const DiskParameters& q, std::vector<double>* out) {
    ++result.evaluations;
    result.pixel_evaluations += static_cast<long>(n);
    out->resize(xs.size());
    for (size_t i = 0; i < xs.size(); i += kLanes) {
      Lanes model, r;
      DiskModelLanes(q, &xs[i], &ys[i], &model, nullptr);
      LoadLanes(&observed[i], &r);
      r -= model;
      std::memcpy(&(*out)[i], &r, sizeof(r));
    }
  };
  // J^T W J and J^T W r at q: per group of kLanes pixels, the model's gradient g in lanes and
  // the upper triangle of the weighted outer product g w g^T accumulated lane-wise; the lanes
  // are summed once at the end. Zero-weight pixels (Tukey outliers, the padding) add zeros.
  auto normal_equations = [&](const DiskParameters& q, Normal* jtj, Vector* jtr) {
    ++result.evaluations;
    result.pixel_evaluations += static_cast<long>(n);
    constexpr int kUpper = kN * (kN + 1) / 2;
    Lanes products[kUpper] = {}, gradient_residual[kN] = {};
    Lanes g[kN];
    for (size_t i = 0; i < xs.size(); i += kLanes) {
      Lanes model, w, wr;
      DiskModelLanes(q, &xs[i], &ys[i], &model, g);
      LoadLanes(&weights[i], &w);
      LoadLanes(&current[i], &wr);
      wr *= w;
      // Fully unrolled, so the 44 accumulators live in registers and stack slots at fixed
      // offsets (a runtime-indexed array costs a load and a store per product).
      int k = 0;
#pragma GCC unroll 8
      for (int row = 0; row < kN; ++row) {
        const Lanes wg = w * g[row];
#pragma GCC unroll 8
        for (int col = row; col < kN; ++col) products[k++] += wg * g[col];
        gradient_residual[row] += wr * g[row];
      }
    }
    const auto sum = [](const Lanes* v) { return ((*v)[0] + (*v)[1]) + ((*v)[2] + (*v)[3]); };
    int k = 0;
    for (int row = 0; row < kN; ++row) {
      for (int col = row; col < kN; ++col)
        (*jtj)(row, col) = (*jtj)(col, row) = sum(&products[k++]);
      (*jtr)(row) = sum(&gradient_residual[row]);
    }
  };
  // Tukey weights at scale tukey_c (plain least squares when tukey_c <= 0) and the weighted cost.
  auto tukey = [](double r, double tukey_c) {
    if (tukey_c <= 0) return 1.0;
    const double u = r / tukey_c;
    return std::abs(u) < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
  };
  auto weigh = [&](const std::vector<double>& residuals, double tukey_c) {
    double cost = 0.0;
    for (size_t i = 0; i < n; ++i) {
      weights[i] = tukey(residuals[i], tukey_c);
      cost += weights[i] * residuals[i] * residuals[i];
    }
    return cost;
  };
  // The weighted cost alone (the trial steps need no weights kept).
  auto weighted_cost = [&](const std::vector<double>& residuals, double tukey_c) {
    double cost = 0.0;
    for (size_t i = 0; i < n; ++i)
      cost += tukey(residuals[i], tukey_c) * residuals[i] * residuals[i];
    return cost;
  };
  // max(floor, 1.4826 median |r|). When at least half the residuals are within the floor (the
  // usual case: the floor is a few percent of the contrast) the answer is the floor and no
  // median is needed; the selection was a fifth of the fit's time.
  auto robust_sigma = [&](const std::vector<double>& residuals, double floor) {
    if (n == 0) return floor;
    const size_t mid = n / 2;  // MedianInPlace's element
    size_t within = 0;
    for (size_t i = 0; i < n; ++i) within += 1.4826 * std::abs(residuals[i]) <= floor ? 1 : 0;
    if (within >= mid + 1) return floor;
    // The `within` residuals below the floor rank below every other, so the median is the
    // (mid - within)-th smallest of the rest: a selection over fewer values, same answer.
    absolute.clear();
    for (size_t i = 0; i < n; ++i) {
      if (1.4826 * std::abs(residuals[i]) > floor) absolute.push_back(std::abs(residuals[i]));
    }
    const size_t rank = mid - within;
    std::nth_element(absolute.begin(), absolute.begin() + rank, absolute.end());
    return std::max(floor, 1.4826 * absolute[rank]);
  };
  gather(p);
  residuals_at(p, &current);
  double last_center_step = 1e9;
  Normal jtj;
  Vector jtr;
  for (int iteration = 0; iteration < max_iterations; ++iteration) {
    result.iterations = iteration + 1;
    // Robust scale: from the residuals, with a floor of a few percent of the contrast so the
    // model's own small misfit along the edge (a real blur is not exactly Gaussian) is never
    // mistaken for occlusion. From a good start (robust_from_start), the first two rounds use
    // a fixed scale of a quarter of the contrast, so pixels the start does not explain (the
    // hidden part of a dot) are outliers from the outset; otherwise the first two rounds are
    // plain least squares.
    const double floor = 0.5 + 0.04 * std::abs(p[6]);
    const double sigma = iteration >= 2 || !robust_from_start
                             ? robust_sigma(current, floor)
                             : std::max(floor, 0.25 * std::abs(p[6]) / 4.685);
    const double tukey_c = iteration >= 2 || robust_from_start ? 4.685 * sigma : -1.0;
    const double cost = weigh(current, tukey_c);
    normal_equations(p, &jtj, &jtr);
    if (fix_shape) {
      jtj.middleRows<4>(2).setZero();
      jtj.middleCols<4>(2).setZero();
      jtr.segment<4>(2).setZero();
      jtj(2, 2) = jtj(3, 3) = jtj(4, 4) = jtj(5, 5) = 1.0;
    }
    bool improved = false;
    Vector step;
    bool settled = false;
    for (int attempt = 0; attempt < 8 && !improved; ++attempt) {
      Normal a = jtj;
      const Vector damping = lambda * jtj.diagonal().cwiseMax(1e-9);
      a.diagonal() += damping;
      step = a.ldlt().solve(jtr);
      if (!std::isfinite(step.sum())) break;
      // The decrease the linearised model promises for this step (Madsen, Nielsen & Tingleff,
      // "Methods for non-linear least squares problems", 2004, eq. 3.14). Below a 1e-9 of the
      // cost no step can improve it measurably: at a minimum, without trying more damping
      // (each try is a pass over the window).
      const double predicted = step.dot(jtr + damping.cwiseProduct(step));
      if (predicted <= 1e-9 * cost) {
        settled = true;
        break;
      }
      DiskParameters q = p;
      for (int k = 0; k < kN; ++k) q[k] += step[k];
      q[2] = std::max(q[2], 1.0 / max_radius);
      q[4] = std::max(q[4], 1.0 / max_radius);
      q[5] = std::clamp(q[5], 0.02, 1.0);
      residuals_at(q, &trial);
      if (weighted_cost(trial, tukey_c) < cost) {
        p = q;
        std::swap(current, trial);
        lambda = std::max(1e-7, lambda * 0.3);
        improved = true;
      } else {
        lambda *= 10.0;
      }
    }
    if (!improved) {  // at a minimum of the current (reweighted) cost
      result.converged = iteration >= 2 || (settled && iteration >= 1);
      break;
    }
    if ((Eigen::Vector2d(p[0], p[1]) - bounds.origin).norm() > bounds.max_travel ||
        (iteration >= 2 && EquivalentRadius(p) > bounds.max_equivalent_radius) ||
        (iteration >= 3 && bounds.abandon_at_width_limit && p[5] >= 1.0)) {
      result.abandoned = true;
      break;
    }
    if (gather(p)) residuals_at(p, &current);  // the window follows the centre
    last_center_step = step.head<2>().norm();
    if (last_center_step < 5e-3 && iteration >= 2) {
      result.converged = true;
      break;
    }
  }
  // Out of iterations but the centre has settled (the shape parameters may still creep).
  if (!result.converged && !result.abandoned && last_center_step < 0.01) result.converged = true;
  if (result.abandoned) {  // no statistics: the caller drops it
    result.p = p;
    return result;
  }
  // Final robust statistics (current holds the residuals at p over the current window).
  result.sigma = robust_sigma(current, 0.5);
  weigh(current, 4.685 * std::max(result.sigma, 0.5 + 0.04 * std::abs(p[6])));
  double weight_sum = 0.0;
  for (size_t i = 0; i < n; ++i) weight_sum += weights[i];
  result.inlier_fraction = n == 0 ? 0.0 : weight_sum / n;
  result.p = p;
  return result;
}

// How well a start explains its window before any fitting: the mean Tukey weight of the
// window's residuals at the fixed scale FitDisk's robust start uses (a quarter of the
// contrast). One residual pass; ranks the occlusion refit's starts so only the best are fitted.
double StartInlierFraction(const cv::Mat& image, const DiskParameters& p, double max_radius) {
  const int half = static_cast<int>(
      std::ceil(std::min(SemiMajorAxis(p) * (1.0 + 3.0 * p[5]), 1.5 * max_radius) + 2.0));
  const int cx = static_cast<int>(std::lround(p[0])), cy = static_cast<int>(std::lround(p[1]));
  const double tukey_c = std::max(4.685 * (0.5 + 0.04 * std::abs(p[6])), 0.25 * std::abs(p[6]));
  double weight_sum = 0.0;
  int count = 0;
  for (int y = std::max(0, cy - half); y <= std::min(image.rows - 1, cy + half); ++y) {
    const uchar* row = image.ptr<uchar>(y);
    for (int x = std::max(0, cx - half); x <= std::min(image.cols - 1, cx + half); ++x) {
      const double u = (row[x] - DiskModel(p, x, y, nullptr)) / tukey_c;
      weight_sum += std::abs(u) < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
      ++count;
    }
  }
  return count > 0 ? weight_sum / count : 0.0;
}

// The fit's start for a candidate at `center` (expected radius r0, start contrast a0 signed as
// the model's a, background b0): the centroid and second moments of the dot's mass, its depth
// beyond the background less a quarter of |a0| (so background noise adds nothing), inside a
// disk of 1.5 r0 + 1 pixels. For a symmetric blurred dot the centroid is unbiased and the
// covariance C is that of the thresholded ellipse, ~ (L^T L)^-1 / 4, so L starts as the
// Cholesky factor of (4 C)^-1 and the fit starts within a few hundredths of a pixel and near
// the dot's shape: fewer iterations than from the band-pass peak. Falls back to the peak and
// a disk of radius r0 when the moments are degenerate.
DiskParameters MomentStart(const cv::Mat& image, const Eigen::Vector2d& center, double r0,
                           double a0, double b0) {
  DiskParameters fallback = {center.x(), center.y(), 1.0 / r0, 0.0, 1.0 / r0, 1.0 / r0, a0, b0};
  const double sign = a0 < 0 ? -1.0 : 1.0, threshold = 0.25 * std::abs(a0);
  const double reach = 1.5 * r0 + 1.0;
  const int cx = static_cast<int>(std::lround(center.x()));
  const int cy = static_cast<int>(std::lround(center.y()));
  const int half = static_cast<int>(std::ceil(reach));
  double mass = 0, mx = 0, my = 0, mxx = 0, mxy = 0, myy = 0, deepest = 0;
  for (int y = std::max(0, cy - half); y <= std::min(image.rows - 1, cy + half); ++y) {
    const uchar* row = image.ptr<uchar>(y);
    const double dy = y - center.y();
    for (int x = std::max(0, cx - half); x <= std::min(image.cols - 1, cx + half); ++x) {
      const double dx = x - center.x();
      if (dx * dx + dy * dy > reach * reach) continue;
      const double depth = sign * (row[x] - b0);
      deepest = std::max(deepest, depth);
      const double m = depth - threshold;
      if (m <= 0) continue;
      mass += m;
      mx += m * dx;
      my += m * dy;
      mxx += m * dx * dx;
      mxy += m * dx * dy;
      myy += m * dy * dy;
    }
  }
  if (!(mass > 0)) return fallback;
  mx /= mass;
  my /= mass;
  Eigen::Matrix2d covariance;
  covariance << mxx / mass - mx * mx, mxy / mass - mx * my, mxy / mass - mx * my,
      myy / mass - my * my;
  if (!(std::hypot(mx, my) < r0) || !(covariance.determinant() > 1e-3) ||
      !(covariance.trace() > 0)) {
    return fallback;
  }
  const Eigen::Matrix2d shape = (4.0 * covariance).inverse();  // L^T L
  const double l11 = std::sqrt(shape(0, 0)), l12 = shape(0, 1) / l11;
  const double l22_squared = shape(1, 1) - l12 * l12;
  if (!(l22_squared > 0)) return fallback;
  const double radius = std::sqrt(std::sqrt((4.0 * covariance).determinant()));
  return {center.x() + mx,
          center.y() + my,
          l11,
          l12,
          std::sqrt(l22_squared),
          1.0 / std::max(radius, 1.0),
          sign * deepest,
          b0};
}

}  // namespace

DiskParameters FitBlurredDisk(const cv::Mat& gray, const DiskParameters& initial, bool fix_shape,
                              int max_iterations, double* inlier_fraction, bool robust_from_start) {
  FACEDYN_CHECK(gray.type() == CV_8UC1, "FitBlurredDisk needs an 8-bit grayscale image");
  const FitResult fit = FitDisk(gray, initial, 100.0, max_iterations, fix_shape, robust_from_start);
  if (inlier_fraction) *inlier_fraction = fit.inlier_fraction;
  return fit.p;
}

double BlurredDiskIntensity(const DiskParameters& p, double x, double y,
                            std::array<double, kDiskParameterCount>* gradient) {
  return DiskModel(p, x, y, gradient ? gradient->data() : nullptr);
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

MarkerDetectionOptions MarkerDetectionOptionsForDiameter(double typical_diameter_px) {
  MarkerDetectionOptions options;
  options.expected_diameter_px = typical_diameter_px;
  options.min_diameter_px = std::max(1.5, 0.4 * typical_diameter_px);
  options.max_diameter_px = 1.5 * typical_diameter_px;
  return options;
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
  // Stage times are this thread's CPU time: on a shared machine wall time would also count
  // other processes.
  const auto thread_cpu_ms = [] {
    timespec now{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
    return 1e3 * now.tv_sec + 1e-6 * now.tv_nsec;
  };
  const auto milliseconds_since = [&](double start) { return thread_cpu_ms() - start; };
  double stage_start = thread_cpu_ms();
  // Candidates: the band-pass on a copy at half resolution when dots are at least 6 px across
  // (3 px there, still resolved): a quarter of the pixels for the two blurs, which were most of
  // this stage. Only the candidates' positions come from it; every fit reads the full image.
  const int search_scale = options.expected_diameter_px >= 6.0 ? 2 : 1;
  // Per-thread buffers reused across images (cv::Mat::create keeps a buffer of the same size):
  // six fresh 0.3-5 MB images per call cost page faults on every image.
  struct Buffers {
    cv::Mat half, search, small, large, response, dilated;
  };
  static thread_local Buffers buffers;
  cv::Mat& search = buffers.search;
  if (search_scale == 2) {
    cv::resize(gray, buffers.half, cv::Size(gray.cols / 2, gray.rows / 2), 0, 0, cv::INTER_AREA);
    buffers.half.convertTo(search, CV_32F);
  } else {
    gray.convertTo(search, CV_32F);
  }
  // Band-pass: small blur minus large blur, signed so dots are positive.
  const double sigma =
      std::max(0.8, 0.5 * options.expected_diameter_px / search_scale / std::sqrt(2.0));
  cv::Mat& small = buffers.small;
  cv::Mat& large = buffers.large;
  cv::GaussianBlur(search, small, cv::Size(0, 0), sigma);
  cv::GaussianBlur(search, large, cv::Size(0, 0), 2.0 * sigma);
  cv::Mat& response = buffers.response;
  if (options.polarity == MarkerPolarity::kDark) {
    cv::subtract(large, small, response);
  } else {
    cv::subtract(small, large, response);
  }
  // Local maxima over a neighbourhood of the smallest dot, above a fraction of min_contrast
  // (the band-pass response of a dot of contrast c is about c/4 at the matched scale).
  const int radius =
      std::max(1, static_cast<int>(std::floor(0.5 * options.min_diameter_px / search_scale)));
  cv::Mat& dilated = buffers.dilated;
  cv::dilate(response, dilated,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * radius + 1, 2 * radius + 1)));
  const float threshold = static_cast<float>(0.15 * options.min_contrast);
  struct Candidate {
    Eigen::Vector2d center_px;  // full resolution, sub-pixel
    double blurred = 0;  // the small-scale blur there: the dot's level, for the initial contrast
  };
  std::vector<Candidate> candidates;
  for (int y = 1; y < response.rows - 1; ++y) {
    const float* r = response.ptr<float>(y);
    const float* d = dilated.ptr<float>(y);
    const float* b = small.ptr<float>(y);
    for (int x = 1; x < response.cols - 1; ++x) {
      if (r[x] > threshold && r[x] >= d[x]) {
        // Sub-pixel peak of the response (a parabola through the neighbours on each axis), in
        // full-resolution pixels: a half-resolution pixel x covers x_full = 2x and 2x + 1, so
        // its centre is 2x + 0.5. The fits start closer and converge in fewer iterations.
        const float* above = response.ptr<float>(y - 1);
        const float* below = response.ptr<float>(y + 1);
        const auto vertex = [](double left, double middle, double right) {
          const double curvature = left - 2.0 * middle + right;
          return curvature < 0 ? std::clamp(0.5 * (left - right) / curvature, -0.5, 0.5) : 0.0;
        };
        const double x_half = x + vertex(r[x - 1], r[x], r[x + 1]);
        const double y_half = y + vertex(above[x], r[x], below[x]);
        const double offset = 0.5 * (search_scale - 1);
        candidates.push_back(
            {Eigen::Vector2d(search_scale * x_half + offset, search_scale * y_half + offset),
             b[x]});
      }
    }
  }
  summary.candidates = static_cast<int>(candidates.size());
  summary.candidates_ms = milliseconds_since(stage_start);
  stage_start = thread_cpu_ms();

  std::vector<MarkerDetection> detections;
  std::vector<double> border;  // scratch, reused by every candidate
  const double max_radius = 0.5 * options.max_diameter_px;
  for (const Candidate& candidate : candidates) {
    const cv::Point c(static_cast<int>(std::lround(candidate.center_px.x())),
                      static_cast<int>(std::lround(candidate.center_px.y())));
    const double r0 = 0.5 * options.expected_diameter_px;
    // Initial background and amplitude from the window border and the centre.
    const int half = static_cast<int>(std::ceil(2.0 * r0 + 2.0));
    border.clear();
    for (int k = -half; k <= half; ++k) {
      for (const cv::Point& q : {cv::Point(c.x + k, c.y - half), cv::Point(c.x + k, c.y + half),
                                 cv::Point(c.x - half, c.y + k), cv::Point(c.x + half, c.y + k)}) {
        if (q.x >= 0 && q.y >= 0 && q.x < gray.cols && q.y < gray.rows) {
          border.push_back(gray.at<uchar>(q));
        }
      }
    }
    const double b0 = MedianInPlace(&border);
    const double a0 = candidate.blurred - b0;
    // A band-pass maximum whose centre is not darker (for dark dots) than its window's border
    // is an edge or texture, not a dot: on the simulated rig's captured faces these were about
    // 250 of 420 candidates per image, each costing a full fit before its contrast rejected it
    // (`facedyn reconstruct` reports the counters in reconstruction.json). A tenth of the
    // minimum contrast is the margin for noise; a real dot's start is ~0.6 of its contrast.
    const double signed_start = options.polarity == MarkerPolarity::kDark ? -a0 : a0;
    if (signed_start < 0.1 * options.min_contrast) {
      ++summary.rejected_contrast;
      continue;
    }
    FitBounds bounds;
    bounds.origin = Eigen::Vector2d(c.x, c.y);
    bounds.max_travel = 2.0 * r0 + 2.0;  // as the rejection below
    // Each axis is clamped at max_radius, so a fit this large is pinned at the largest dot
    // allowed: on the simulated rig's captured faces, the dark mouth opening and nostrils (a
    // sixth of the fits' pixels, most never converging, the rest accepted as false dots).
    bounds.max_equivalent_radius = 0.98 * max_radius;
    bounds.abandon_at_width_limit = true;
    // The start's moments measure the candidate's mass within 1.5 r0 + 1 px. Mass wider than the
    // largest dot allowed is shading, not a dot (a shading blob fills the moment window): on the
    // simulated rig's captured faces such candidates were most of the candidates fitted and
    // rejected, and three quarters of the fits' time. Rejected before fitting, as its fit
    // would be (a dot it could still be is at least max_radius wide).
    const DiskParameters start = MomentStart(gray, candidate.center_px, r0, a0, b0);
    if (EquivalentRadius(start) > max_radius) {
      ++summary.rejected_size;
      ++summary.rejected_size_unfitted;
      continue;
    }
    const FitResult fit =
        FitDisk(gray, start, max_radius, options.max_iterations, false, false, bounds);
    ++summary.fits;
    summary.fit_iterations += fit.iterations;
    summary.fit_evaluations += fit.evaluations;
    summary.fit_pixel_evaluations += fit.pixel_evaluations;
    const double contrast = options.polarity == MarkerPolarity::kDark ? -fit.p[6] : fit.p[6];
    if (!fit.converged ||
        (Eigen::Vector2d(fit.p[0], fit.p[1]) - bounds.origin).norm() > bounds.max_travel) {
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
  summary.fit_ms = milliseconds_since(stage_start);
  stage_start = thread_cpu_ms();
  std::vector<MarkerDetection> refitted = detections;
  for (size_t i = 0; i < detections.size() && options.occlusion_refit; ++i) {
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
    shape[2] = MedianInPlace(&l11);
    shape[3] = MedianInPlace(&l12);
    shape[4] = MedianInPlace(&l22);
    const double scale = EquivalentRadius(shape) / reference_radius;
    shape[2] *= scale;
    shape[3] *= scale;
    shape[4] *= scale;
    shape[5] = MedianInPlace(&widths);
    // The shrunken fit hugs the visible part, so the true centre lies about
    // (reference - fitted radius) away in an unknown direction: start there in 8 directions
    // (and in place) and keep the fit that explains the most pixels.
    FitResult fit;
    fit.inlier_fraction = -1.0;
    const double offset = reference_radius - detections[i].radius_px;
    // Each start is first scored by how much of its window it already explains (one pass);
    // only the best is fitted. Fitting all nine cost more than the first fits of every dot in
    // the image (reconstruct_bench's per_image_ms), and fitting the best three kept more wrong
    // refits than the best one (reconstruct_bench centre RMS 0.178 against 0.150 px; a
    // captured sim8 take's reprojection RMS 0.284 against 0.216 px).
    constexpr int kOcclusionStartsFitted = 1;
    // Its window must reach the dot's hidden side from a start `offset` away from the centre.
    FitBounds refit_bounds;
    refit_bounds.window_margin_px = offset + 2.0;
    std::array<std::pair<double, DiskParameters>, 9> starts;
    for (int direction = -1; direction < 8; ++direction) {
      DiskParameters p = shape;
      if (direction >= 0) {
        p[0] += offset * std::cos(M_PI / 4 * direction);
        p[1] += offset * std::sin(M_PI / 4 * direction);
      }
      starts[direction + 1] = {StartInlierFraction(gray, p, max_radius), p};
    }
    std::partial_sort(starts.begin(), starts.begin() + kOcclusionStartsFitted, starts.end(),
                      [](const auto& a, const auto& b) { return a.first > b.first; });
    for (int s = 0; s < kOcclusionStartsFitted; ++s) {
      const FitResult candidate = FitDisk(gray, starts[s].second, max_radius,
                                          options.max_iterations, true, true, refit_bounds);
      ++summary.occlusion_fits;
      summary.occlusion_iterations += candidate.iterations;
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
    ++summary.refitted_for_occlusion;
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
  summary.occlusion_ms = milliseconds_since(stage_start);
  return unique;
}

std::vector<StatusOr<std::vector<MarkerDetection>>> DetectMarkersInImages(
    const std::vector<cv::Mat>& images, const MarkerDetectionOptions& options, int threads,
    std::vector<MarkerDetectionSummary>* summaries) {
  std::vector<StatusOr<std::vector<MarkerDetection>>> results(
      images.size(), StatusOr<std::vector<MarkerDetection>>(InternalError("not run")));
  if (summaries) summaries->assign(images.size(), MarkerDetectionSummary());
  if (threads <= 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = std::min<int>(threads, static_cast<int>(images.size()));
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i = next++; i < images.size(); i = next++) {
      results[i] = images[i].empty()
                       ? StatusOr<std::vector<MarkerDetection>>(std::vector<MarkerDetection>())
                       : DetectMarkers(images[i], options, summaries ? &(*summaries)[i] : nullptr);
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& thread : pool) thread.join();
  return results;
}

}  // namespace facedyn::reconstruct
