// Painted-marker detection: sub-pixel centres of round dots in a grayscale image, each with a
// quality score.
//
// Two stages. (1) Candidates: a difference-of-Gaussians band-pass tuned to the expected dot
// size (for a disk of radius R the Laplacian-of-Gaussian response peaks at sigma = R/sqrt 2)
// and local extrema of the response above a contrast threshold. (2) Each candidate is refined
// by fitting a blurred-ellipse model to the pixels of a window around it (a round dot seen at
// an angle is an ellipse):
//   I(x, y) = b + a * Phi((1 - rho) / w),   rho = |L ((x, y) - (x0, y0))|,
// L = [l11 l12; 0 l22] mapping the ellipse to the unit disk, w the edge width in those units,
// Phi the standard normal CDF (an ellipse seen through a Gaussian blur, to first order in w),
// by Levenberg-Marquardt with iteratively reweighted residuals (Tukey's
// biweight at 4.685 robust sigmas). A symmetric model fits a blurred dot without bias, and the
// robust weights make pixels that do not belong to the dot (an occluding eyelash or edge, a
// neighbouring dot at the window border) stop pulling the centre. The window follows the
// centre as it moves.
//
// Optionally (MarkerDetectionOptions::occlusion_refit, off by default), a dot clearly smaller
// than its neighbours that leaves part of its window unexplained is taken as partly hidden: it
// is refitted with the neighbours' shape held, and the refit is kept when it explains the
// window about as well as the free fit. See the .cc.
//
// Quality in [0, 1]: (weighted fraction of window pixels the model explains) *
// |a| / (|a| + 3 sigma_residual), i.e. near 1 for a clean, contrasty, fully visible dot, lower
// when part of it is hidden or the image is noisy. Detections below min_quality, with a radius
// outside [min_diameter_px, max_diameter_px] / 2, with contrast below min_contrast, or whose
// fit did not converge are dropped (the summary counts why).
#pragma once

#include <Eigen/Core>
#include <array>
#include <opencv2/core.hpp>
#include <vector>

#include "core/status.h"

namespace facedyn::reconstruct {

enum class MarkerPolarity { kDark, kBright };

struct MarkerDetectionOptions {
  MarkerPolarity polarity = MarkerPolarity::kDark;
  double min_diameter_px = 3.0;
  double max_diameter_px = 24.0;
  double expected_diameter_px = 8.0;  // tunes the band-pass; within [min, max]
  double min_contrast = 12.0;         // |a|, gray levels
  double min_quality = 0.4;
  int max_iterations = 20;
  // Refit dots clearly smaller than their neighbours with the neighbours' shape (occlusion,
  // see above). Off by default: its premise, that neighbouring dots share a shape, fails
  // wherever the surface turns (a dot seen more obliquely than its neighbours looks smaller
  // without being hidden), and on every image path measured it moved more centres away from
  // the truth than towards it. Side by side with and without it (the refit fitting its best
  // start only): reconstruct_bench's rendered rig, centre RMS 0.150 -> 0.066 px and 3D
  // marker RMS 0.030 -> 0.014 mm; a captured 8-frame take of config/capture/sim8.yaml,
  // reprojection RMS 0.216 -> 0.054 px; the simulated HMC's dialogue, 0.128 -> 0.042 px
  // (reconstruct/session_input.h). Worth trying where real occluders (hair, a lip over a dot)
  // are common and the surface is flat around the markers.
  bool occlusion_refit = false;
  Status Check() const;
};

// Options for dots of a typical diameter in the images: the band-pass tuned to it, and
// diameters from 0.4x to 1.5x accepted. On the simulated rig's captured faces
// (config/capture/sim8.yaml, --marker-diameter-px 9) the real dots' fitted radii span 0.5-1.1x
// the typical one (1st-99th percentile of 5,800 fits), while what converges between 1.5x and
// the earlier bound of 2.5x is shading (a nostril's edge, the mouth's corner: contrast near the
// minimum). The bound also decides which candidates are fitted at all (see DetectMarkers).
MarkerDetectionOptions MarkerDetectionOptionsForDiameter(double typical_diameter_px);

struct MarkerDetection {
  Eigen::Vector2d center_px = Eigen::Vector2d::Zero();
  double radius_px = 0.0;      // of the disk with the ellipse's area
  double edge_width_px = 0.0;  // blur width at the edge, pixels
  double contrast = 0.0;       // |a|
  double quality = 0.0;
  double residual_rms = 0.0;         // robust sigma of the fit residuals, gray levels
  bool refit_for_occlusion = false;  // radius held at the neighbours' (see above)
  double inlier_fraction = 0.0;      // mean robust weight of the window's pixels
  std::array<double, 8> fit{};       // (x0, y0, l11, l12, l22, w, a, b)
};

struct MarkerDetectionSummary {
  int candidates = 0;
  int accepted = 0;
  int rejected_fit = 0;  // did not converge, or left its window
  int rejected_size = 0;
  // Of those, never fitted: the candidate's dark (or bright) mass, measured by its moments in
  // the start, was already wider than the largest dot allowed.
  int rejected_size_unfitted = 0;
  int rejected_contrast = 0;
  int rejected_quality = 0;
  int duplicates = 0;
  int fits = 0;                    // candidates fitted (the rest were rejected before)
  int fit_iterations = 0;          // of the first fits, summed over candidates
  int fit_evaluations = 0;         // model evaluations over a window in those fits
  long fit_pixel_evaluations = 0;  // pixels x evaluations in those fits
  int occlusion_fits = 0;        // fits tried for suspected occlusion (several starts per suspect)
  int occlusion_iterations = 0;  // summed over those fits
  int refitted_for_occlusion = 0;  // detections whose occlusion refit was kept
  // CPU time of each stage in this call (the calling thread's), milliseconds, for
  // reconstruct_bench's profile.
  double candidates_ms = 0.0;  // band-pass and local maxima
  double fit_ms = 0.0;         // the blurred-ellipse fits
  double occlusion_ms = 0.0;   // the occlusion refits and the duplicate merge
};

// Detects markers in an 8-bit grayscale image. InvalidArgument for an empty or non-8-bit image
// or bad options.
StatusOr<std::vector<MarkerDetection>> DetectMarkers(const cv::Mat& gray,
                                                     const MarkerDetectionOptions& options,
                                                     MarkerDetectionSummary* summary = nullptr);

// DetectMarkers on several images (one per camera) on up to `threads` threads (0 = the
// machine's hardware threads); results in image order. `summaries`, when given, receives one
// summary per image (empty images: all zero).
std::vector<StatusOr<std::vector<MarkerDetection>>> DetectMarkersInImages(
    const std::vector<cv::Mat>& images, const MarkerDetectionOptions& options, int threads = 0,
    std::vector<MarkerDetectionSummary>* summaries = nullptr);

// The blurred-ellipse model and its gradient with respect to
// p = (x0, y0, l11, l12, l22, w, a, b), at pixel (x, y). Exposed for the gradient test.
inline constexpr int kDiskParameterCount = 8;
using DiskParameters = std::array<double, kDiskParameterCount>;
double BlurredDiskIntensity(const DiskParameters& p, double x, double y,
                            std::array<double, kDiskParameterCount>* gradient = nullptr);

// The robust fit of one dot from `initial` (exposed for tests); `fix_shape` holds L and w.
DiskParameters FitBlurredDisk(const cv::Mat& gray, const DiskParameters& initial, bool fix_shape,
                              int max_iterations = 20, double* inlier_fraction = nullptr,
                              bool robust_from_start = false);

}  // namespace facedyn::reconstruct
