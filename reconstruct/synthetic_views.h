// Synthetic cameras and images with known truth, for tests, benches and the simulated stage:
// a ring of cameras around a subject, planar targets rendered through a camera (lens
// distortion included), and painted dots rendered as a camera would see them.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <random>
#include <vector>

#include "core/face_rig.h"
#include "core/rigid3.h"
#include "reconstruct/camera.h"
#include "reconstruct/triangulation.h"

namespace facedyn::reconstruct {

struct CameraRingOptions {
  int camera_count = 8;
  double radius_mm = 600.0;     // distance of each centre from the target
  double arc_deg = 120.0;       // cameras spread over this horizontal arc, centred on +Z
  double elevation_deg = 15.0;  // alternate cameras sit this much above / below the equator
  int width_px = 1280;
  int height_px = 1024;
  double focal_px = 2600.0;
  Eigen::Vector3d target_in_world = Eigen::Vector3d::Zero();
};

// Cameras on an arc in front of the target (the face looks along +Z, world +Y up), all looking
// at it, named cam0..camN-1.
std::vector<Camera> MakeCameraRing(const CameraRingOptions& options);

// The viewing ray (camera frame, z = 1) of every sub-pixel of a camera's image, supersampled
// `supersample`^2 times per pixel: computed once per camera (Camera::Undistort per sample) and
// reused for every rendered view.
struct CameraRays {
  Camera camera;
  int supersample = 1;
  std::vector<Eigen::Vector2f> normalized;  // row-major, (width * s) x (height * s)
};
CameraRays MakeCameraRays(const Camera& camera, int supersample = 2);

// The simulated stage's capture rig: `camera_count` 1280x1024 cameras on a 120-degree arc
// 600 mm in front of a face at rest (f = 2200 px, k1 = -0.06, k2 = 0.02), alternately 12
// degrees above and 8 below, all looking at (0, -15, 60) mm (mid-face, skull frame at rest).
std::vector<Camera> MakeFaceCameraRing(int camera_count = 8);

// The view through a camera of a planar texture (8-bit gray, `pixels_per_mm`, its pixel
// (0, 0) centred at board point (-margin_mm, -margin_mm) + half a texel) lying in the
// board's z = 0 plane at `world_from_board`. Every (sub-)pixel's ray is traced back through
// the lens to the plane and sampled bilinearly; rays that miss the texture see `background`.
cv::Mat RenderPlanarView(const cv::Mat& texture, double pixels_per_mm, double margin_mm,
                         const CameraRays& rays, const Rigid3& world_from_board,
                         unsigned char background = 128);
// One-off form (computes the rays).
cv::Mat RenderPlanarView(const cv::Mat& texture, double pixels_per_mm, double margin_mm,
                         const Camera& camera, const Rigid3& world_from_board, int supersample = 2,
                         unsigned char background = 128);

// Filled polygons (pixel coordinates, (0,0) = centre of the top-left pixel) of `ink` on
// `background`, drawn on a canvas `supersample` times finer and area-averaged down, so edges
// carry exact partial coverage: painted dots as a camera sees them before lens blur.
cv::Mat RenderPolygons(int width_px, int height_px,
                       const std::vector<std::vector<Eigen::Vector2d>>& polygons,
                       unsigned char background, unsigned char ink, int supersample = 8);
// `vertex_count` points on a circle.
std::vector<Eigen::Vector2d> CircleOutline(const Eigen::Vector2d& center_px, double radius_px,
                                           int vertex_count = 48);
// The image outline of a flat disk (a painted marker) of `radius_mm` at `center_in_world`
// with unit normal `normal_in_world`; empty when it faces away from the camera or is behind it.
std::vector<Eigen::Vector2d> ProjectDiskOutline(const Camera& camera,
                                                const Eigen::Vector3d& center_in_world,
                                                const Eigen::Vector3d& normal_in_world,
                                                double radius_mm, int vertex_count = 32);


// A rig's painted markers on a skin surface (3 x V, world): positions and unit normals.
Eigen::Matrix3Xd MarkerPositions(const FaceRig& rig, const Eigen::Matrix3Xd& skin_in_world);
Eigen::Matrix3Xd MarkerNormals(const FaceRig& rig, const Eigen::Matrix3Xd& skin_in_world);

// Ideal detections of markers: every marker facing a camera (normal towards it with cosine
// above `min_cos`) and inside its image (4 px margin) is projected, with Gaussian noise of
// `sigma_px` per axis; each camera's list is shuffled (a detector reports no identities).
// truth[c][i] is the marker index of detections[c][i].
struct MarkerViews {
  std::vector<std::vector<ImageObservation>> detections;
  std::vector<std::vector<int>> truth;
};
MarkerViews ProjectMarkers(const std::vector<Camera>& cameras, const Eigen::Matrix3Xd& markers,
                           const Eigen::Matrix3Xd& normals, double sigma_px, std::mt19937* rng,
                           double min_cos = 0.2);

// Adds zero-mean Gaussian noise of `sigma` gray levels to an 8-bit image (saturating).
void AddImageNoise(double sigma, std::mt19937* rng, cv::Mat* image);

}  // namespace facedyn::reconstruct
