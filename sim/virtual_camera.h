// Virtual cameras: the simulated face filmed by calibrated cameras, and a capture::Camera
// backend that delivers those images at trigger times.
//
// Image formation, per camera and frame (all in linear radiance in [0, 1] until the end):
//   1. Geometry: every skin vertex is projected with the full camera model (pinhole + OpenCV
//      distortion, capture/camera_model.h); triangles are rasterised between the distorted
//      vertex positions. Triangles of the simulated faces span a few pixels, over which the
//      distortion field is linear to far below a pixel, so this is exact for practical
//      purposes and keeps the inner loop a plain edge-function rasteriser.
//   2. Visibility: a z-buffer (depth = Z in the camera, interpolated perspective-correctly)
//      resolves self-occlusion (nose over cheek, lips); back faces are culled.
//   3. Shading: Lambertian skin lit by a ring light at the camera (the usual capture-rig
//      light) plus ambient, evaluated per vertex and interpolated (Gouraud).
//   4. Painted markers (FaceRig::markers): dots of diameter_mm painted on the skin. A pixel's
//      surface point is interpolated in rest-pose (neutral, skull-frame) coordinates, which
//      move with the skin like paint does, and a pixel is dark when that point is within the
//      marker's radius of the marker's rest position, with an anti-aliased edge one pixel
//      footprint wide. Each triangle carries the few markers that can touch it, so triangles
//      without markers pay nothing.
//   5. Optional motion blur: the radiance is averaged over `motion_blur_samples` instants
//      spread over the exposure (the caller supplies the positions at each instant).
//   6. Optics and sensor: an optional Gaussian PSF (blur_sigma_px), then DN = 255 x radiance
//      x gain, plus Gaussian read noise and signal-dependent shot noise, rounded and clamped
//      to mono8. Noise is a deterministic function of (seed, camera, trigger, pixel).
// The hot loop has no virtual calls and no per-frame allocation (buffers live in the
// FaceRenderer's per-thread Workspace).
#pragma once

#include <Eigen/Core>
#include <array>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "capture/camera.h"
#include "capture/camera_model.h"
#include "core/face_rig.h"
#include "core/status.h"
#include "core/take.h"

namespace facedyn::sim {

struct RenderOptions {
  double skin_albedo = 0.72;
  double marker_albedo = 0.06;    // painted dots are dark
  double background = 0.04;       // radiance of everything that is not skin
  double ambient = 0.22;          // fraction of the light that is ambient
  double gain = 1.0;              // exposure gain on radiance before quantisation
  double read_noise_dn = 1.2;     // sigma of the additive read noise, DN (8-bit)
  double shot_noise_gain = 0.25;  // shot-noise variance per DN of signal (DN)
  double blur_sigma_px = 0.6;     // Gaussian PSF sigma in pixels (0 = none)
  int motion_blur_samples = 1;    // instants averaged over the exposure (1 = no motion blur)
  int supersample = 1;            // render at N x N the resolution and box-filter down (1..4)
  uint64_t seed = 1;

  Status Check() const;  // names the field
};

// Radiance, depth and per-pixel scratch for one resolution; reused across frames.
struct RenderWorkspace {
  int width_px = 0;
  int height_px = 0;
  std::vector<float> radiance;   // accumulated radiance (valid once an instant is accumulated)
  std::vector<float> sample;     // one instant's radiance
  int instants = 0;              // accumulated since BeginFrame
  std::vector<float> depth_mm;   // z-buffer of the last instant rendered (inf = nothing)
  std::vector<float> projected;  // 3 x V: u, v, Z per vertex
  std::vector<float> shade;      // per-vertex shading
  Eigen::Matrix3Xd normals;
  void Resize(int width, int height, int vertices);
};

// Renders one FaceRig's skin. Thread-safe for concurrent Render calls with separate
// workspaces (the renderer itself is immutable after construction).
class FaceRenderer {
 public:
  FaceRenderer(const FaceRig& rig, const RenderOptions& options);

  int vertex_count() const { return rest_.cols(); }
  const RenderOptions& options() const { return options_; }

  // Accumulates `weight` x the radiance of the skin at `positions_in_world` (3 x V, mm) as
  // seen by `camera` into workspace->radiance (sized by camera and supersample; call
  // BeginFrame first). Leaves that instant's z-buffer in workspace->depth_mm.
  void BeginFrame(const capture::CameraModel& camera, RenderWorkspace* workspace) const;
  void AccumulateInstant(const capture::CameraModel& camera,
                         const Eigen::Matrix3Xd& positions_in_world, float weight,
                         RenderWorkspace* workspace) const;
  // PSF, noise and quantisation into `out` (camera.width_px x height_px, mono8).
  // `noise_key` makes the noise differ between cameras and triggers.
  void FinishFrame(const capture::CameraModel& camera, uint64_t noise_key,
                   RenderWorkspace* workspace, uint8_t* out) const;

  // Convenience: one instant, the whole pipeline.
  void Render(const capture::CameraModel& camera, const Eigen::Matrix3Xd& positions_in_world,
              uint64_t noise_key, RenderWorkspace* workspace, uint8_t* out) const;

  // Rest-pose (skull frame) marker centres, for tests and ground truth.
  const Eigen::Matrix3Xd& marker_rest_positions() const { return marker_rest_; }

 private:
  RenderOptions options_;
  Eigen::Matrix3Xi triangles_;
  Eigen::Matrix3Xd rest_;  // neutral positions, the paint's coordinates
  Eigen::Matrix3Xd marker_rest_;
  std::vector<double> marker_radius_mm_;
  // CSR lists of the dots that can touch each triangle: per (triangle, dot), the squared
  // rest-pose distance to the dot's centre as a quadratic in the first two barycentrics,
  // c0 + c1 w0 + c2 w1 + c3 w0^2 + c4 w0 w1 + c5 w1^2, and the dot's radius.
  struct MarkerTerm {
    std::array<float, 6> c{};
    float radius_mm = 0.0f;
  };
  std::vector<int> triangle_marker_offsets_;
  std::vector<MarkerTerm> marker_terms_;
  bool outward_ccw_ = true;  // winding of the front side
};

// Sensor stage shared with the calibration-target renderer: PSF, noise, quantisation of a
// radiance image of the camera's size (supersampled images are box-filtered first).
void FinishRadiance(const RenderOptions& options, int width_px, int height_px, int supersample,
                    uint64_t noise_key, std::vector<float>* radiance, uint8_t* out);

// Faults a simulated camera can inject, to exercise the sync checks.
struct SimCameraFaults {
  std::set<int64_t> drop_triggers;       // never delivered
  std::set<int64_t> duplicate_triggers;  // delivered twice
  std::set<int64_t> late_triggers;       // delivered after the next trigger's frame
  int64_t timestamp_offset_ns = 0;       // added to every timestamp
};

// A capture::Camera that renders a simulated take. Trigger k shows take frame k (the take's
// fps must equal the trigger rate; the take must cover every trigger). OnTrigger queues the
// trigger (waiting while 8 are pending, which is safe on a virtual clock); NextFrame renders
// on the calling thread.
class SimCamera : public capture::Camera {
 public:
  SimCamera(int camera_index, capture::CameraModel model,
            std::shared_ptr<const FaceRenderer> renderer, std::shared_ptr<const Take> take,
            SimCameraFaults faults = {});

  const std::string& name() const override { return model_.name; }
  std::string backend() const override { return "sim"; }
  Status Configure(const capture::CameraSettings& settings) override;
  const capture::CameraSettings& settings() const override { return settings_; }
  Status Arm() override;
  Status OnTrigger(const capture::TriggerEvent& trigger) override;
  Status NextFrame(double timeout_s, capture::Frame* frame, bool* got_frame) override;
  Status Disarm() override;

  const capture::CameraModel& model() const { return model_; }
  // Seconds spent rendering so far (for frames/s figures).
  double render_s() const { return render_s_; }

 private:
  Status RenderTrigger(const capture::TriggerEvent& trigger, capture::Frame* frame);

  int camera_index_;
  capture::CameraModel model_;
  std::shared_ptr<const FaceRenderer> renderer_;
  std::shared_ptr<const Take> take_;
  SimCameraFaults faults_;
  capture::CameraSettings settings_;
  RenderWorkspace workspace_;
  bool configured_ = false;
  bool armed_ = false;

  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<capture::TriggerEvent> pending_;
  bool disarmed_ = false;
  // Delivery state for faults.
  bool has_late_ = false;
  capture::Frame late_frame_;
  bool has_repeat_ = false;
  capture::Frame repeat_frame_;
  double render_s_ = 0.0;
  // Per-frame position buffers, reused (no allocation per frame once sized).
  Eigen::Matrix3Xd positions_, current_, next_;
};

}  // namespace facedyn::sim
