// Features of Zoss et al. 2020 ("Data-driven Extraction and Composition of Secondary Dynamics
// in Facial Performance Capture", sections 5.1 and 6.1): the skull descriptor B(t) (Eq. 1-2),
// the per-sample skin descriptor X_i(t) (Eq. 3-4) and the per-sample surface stretch S(t)
// (Eq. 8). They are computed for a whole take at once, so the per-frame work is a few Eigen
// column operations over buffers allocated once per take.
//
// Windows are set in time and converted to frames with the take's fps
// (FeatureConfig::window_frames(): round(window_s * fps), 10 at 128 fps, 8 at 96 fps), so a
// model trained at one frame rate knows which window it was trained with.
//
// End-of-take policy (every function here and in quasistatic.h / baselines.h): a take is
// treated as if its first and last frames were held forever, i.e. every frame index is clamped
// to [0, F-1] before poses or positions are read. Velocities (Eq. 2, 4) are differences of
// clamped frames, so they are zero outside [1, F-1]. Nothing reads outside the arrays, and a
// take of a single frame is valid (all velocities zero).
//
// Frames and units: positions in mm; velocities in mm/s, in the canonical (skull) frame;
// stretch is dimensionless (relative length change).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/face_rig.h"
#include "core/rigid3.h"
#include "core/status.h"
#include "core/take.h"

namespace facedyn::dynamics {

// Clamps a frame index into [0, frame_count - 1] (the end-of-take policy above).
// Precondition: frame_count >= 1.
inline int ClampFrame(int frame, int frame_count) {
  return frame < 0 ? 0 : (frame >= frame_count ? frame_count - 1 : frame);
}

// Half-window in frames for a half-window in seconds: round(window_s * fps).
int WindowFrames(double window_s, double fps);

// What a feature vector means: saved with a model so it can refuse an incompatible take.
struct FeatureConfig {
  double fps = 128.0;           // frame rate the features are computed at, Hz
  double window_s = 0.08;       // half-window of B and X (the paper's w_b = w_x), seconds
  double stretch_step_mm = 2.0;  // uv step of the stretch stencil on the neutral, mm (Eq. 8)

  // fps > 0, window_s in [0, 1] s, stretch_step_mm in (0, 50]. Messages name the field.
  Status Check() const;

  int window_frames() const { return WindowFrames(window_s, fps); }
  int window_length() const { return 2 * window_frames() + 1; }
  // Size of B(t) for `landmark_count` landmarks: landmark_count * (2w+1) * 3.
  int SkullDescriptorSize(int landmark_count) const {
    return landmark_count * window_length() * 3;
  }
  // Size of X_i(t): (2w+1) * 3.
  int SkinDescriptorSize() const { return window_length() * 3; }
};

// FailedPrecondition when the take's fps differs from config.fps (relative 1e-6).
Status CheckTakeMatchesConfig(const Take& take, const FeatureConfig& config);

// Per-frame skull landmark velocities, Eq. (2): column t holds, for each landmark i, the
// 3-vector [I - T(t)^-1 T(t-1)] b_i / dt with T = world_from_skull and dt = 1/fps, in the
// skull frame (mm/s). Rows 3i..3i+2 are landmark i. Column 0 is zero (end policy).
// Preconditions: fps > 0, world_from_skull non-empty.
Eigen::MatrixXd SkullLandmarkVelocities(const std::vector<Rigid3>& world_from_skull,
                                        const std::vector<Eigen::Vector3d>& landmarks_in_skull,
                                        double fps);

// B(t) of Eq. (1) for every frame: a (L * (2w+1) * 3) x F matrix. Column t is landmark-major:
// for landmark i, window offset j = -w..w, the velocity of frame clamp-policy(t + j), so
// entry [(i * (2w+1) + (j + w)) * 3 + c]. Velocities outside [1, F-1] are zero.
StatusOr<Eigen::MatrixXd> SkullDescriptors(const std::vector<Rigid3>& world_from_skull,
                                           const std::vector<SkullLandmark>& landmarks,
                                           const FeatureConfig& config);

// Positions of surface points in the skull frame, T(t)^-1 x_i(t): 3S x F (rows 3i..3i+2 are
// point i). Errors when a point's vertex is out of range for the take.
StatusOr<Eigen::MatrixXd> StabilisedPointPositions(const Take& take,
                                                   const std::vector<SurfacePoint>& points);

// Stabilised velocities, Eq. (4): column t = (P(t) - P(t-1)) * fps for a 3S x F matrix of
// skull-frame positions P; column 0 is zero. Precondition: fps > 0.
Eigen::MatrixXd StabilisedVelocities(const Eigen::MatrixXd& positions_in_skull, double fps);

// X_i(t) of Eq. (3) for every sample and frame: a ((2w+1) * 3) x (F * S) matrix whose column
// t * S + i is sample i at frame t: entry [(j + w) * 3 + c] is the stabilised velocity of
// frame t + j (zero outside [1, F-1]). Checks the take's fps against the config.
StatusOr<Eigen::MatrixXd> SkinDescriptors(const Take& take, const std::vector<SurfacePoint>& samples,
                                          const FeatureConfig& config);

// The uv stencil of Eq. (8) for each sample: four surface points at the sample's uv
// +- du e_u and +- dv e_v, with du, dv chosen so that each step is about `step_mm` on the
// neutral (from the local uv Jacobian of the sample's triangle). Near a hole or the border,
// where a stencil point leaves the uv chart, the step is halved (up to 4 times) and then the
// sample itself is used on that side (one-sided difference). Reference lengths
// |Delta_u y(0)|, |Delta_v y(0)| are measured on the neutral.
struct StretchStencil {
  int vertex_count = 0;
  std::vector<SurfacePoint> u_minus, u_plus, v_minus, v_plus;  // one per sample
  Eigen::Matrix2Xd rest_length_mm;  // 2 x S: |Delta_u|, |Delta_v| on the neutral
  int sample_count() const { return static_cast<int>(u_minus.size()); }
};

// Builds the stencil from the rig's neutral mesh and its per-vertex UVs (one chart).
// Errors: no UVs, a sample outside the mesh, a degenerate uv triangle at a sample.
StatusOr<StretchStencil> BuildStretchStencil(const FaceRig& rig,
                                             const std::vector<SurfacePoint>& samples,
                                             double step_mm);

// s_i = [(|Delta_u y_i| - |Delta_u y_i(0)|) / |Delta_u y_i(0)|, same for v], Eq. (8), for
// the skin positions of one frame (3 x V, any rigid frame: stretch is rigid-invariant).
// Writes 2 * S values to `stretch_out` (sample-major: u then v). No allocation.
void EvaluateStretch(const StretchStencil& stencil,
                     const Eigen::Ref<const Eigen::Matrix3Xf>& positions_mm, double* stretch_out);

// S(t) for every frame of a take: 2S x F. Errors when the stencil's vertex count differs.
StatusOr<Eigen::MatrixXd> StretchFeatures(const Take& take, const StretchStencil& stencil);

}  // namespace facedyn::dynamics
