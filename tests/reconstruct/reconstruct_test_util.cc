#include "tests/reconstruct/reconstruct_test_util.h"

#include <algorithm>
#include <numeric>

#include "sim/face_anatomy.h"
#include "sim/procedural_face.h"

namespace facedyn::reconstruct::testing {

const FaceRig& ProceduralFace() {
  static const FaceRig* rig =
      new FaceRig(sim::MakeProceduralFace(sim::ProceduralFaceOptions()).value());
  return *rig;
}

std::vector<Camera> FaceCameraRing(int camera_count) {
  std::vector<Camera> cameras;
  const Eigen::Vector3d target(0.0, -15.0, 60.0);
  for (int i = 0; i < camera_count; ++i) {
    const double t = camera_count == 1 ? 0.5 : i / (camera_count - 1.0);
    const double azimuth = (t - 0.5) * 120.0 * M_PI / 180.0;
    const double elevation = (i % 2 == 0 ? 12.0 : -8.0) * M_PI / 180.0;
    const Eigen::Vector3d direction(std::sin(azimuth) * std::cos(elevation), std::sin(elevation),
                                    std::cos(azimuth) * std::cos(elevation));
    Camera camera = Camera::LookAt("cam" + std::to_string(i), 1280, 1024, 2200.0,
                                   target + 600.0 * direction, target, Eigen::Vector3d::UnitY());
    camera.intrinsics[4] = -0.06;
    camera.intrinsics[5] = 0.02;
    cameras.push_back(camera);
  }
  return cameras;
}

Eigen::Matrix3Xd MarkerPositions(const FaceRig& rig, const Eigen::Matrix3Xd& skin_in_world) {
  Eigen::Matrix3Xd markers(3, rig.markers.size());
  for (size_t m = 0; m < rig.markers.size(); ++m) {
    markers.col(m) = rig.markers[m].point.Evaluate(skin_in_world);
  }
  return markers;
}

Eigen::Matrix3Xd MarkerNormals(const FaceRig& rig, const Eigen::Matrix3Xd& skin_in_world) {
  const Eigen::Matrix3Xd vertex_normals = sim::VertexNormals(rig.neutral, skin_in_world);
  Eigen::Matrix3Xd normals(3, rig.markers.size());
  for (size_t m = 0; m < rig.markers.size(); ++m) {
    normals.col(m) = rig.markers[m].point.Evaluate(vertex_normals).normalized();
  }
  return normals;
}

MarkerViews ProjectMarkers(const std::vector<Camera>& cameras, const Eigen::Matrix3Xd& markers,
                           const Eigen::Matrix3Xd& normals, double sigma_px, std::mt19937* rng,
                           double min_cos) {
  std::normal_distribution<double> noise(0.0, sigma_px);
  MarkerViews views;
  for (size_t c = 0; c < cameras.size(); ++c) {
    std::vector<std::pair<ImageObservation, int>> seen;
    for (int m = 0; m < markers.cols(); ++m) {
      const Eigen::Vector3d to_camera = (cameras[c].CenterInWorld() - markers.col(m)).normalized();
      if (normals.col(m).dot(to_camera) < min_cos) continue;
      Eigen::Vector2d pixel;
      if (!cameras[c].Project(markers.col(m), &pixel) || !cameras[c].InImage(pixel, 4)) continue;
      ImageObservation o;
      o.camera = static_cast<int>(c);
      o.pixel = pixel + Eigen::Vector2d(noise(*rng), noise(*rng));
      o.weight = 1.0;
      seen.emplace_back(o, m);
    }
    std::shuffle(seen.begin(), seen.end(), *rng);
    views.detections.emplace_back();
    views.truth.emplace_back();
    for (size_t i = 0; i < seen.size(); ++i) {
      seen[i].first.detection = static_cast<int>(i);
      views.detections.back().push_back(seen[i].first);
      views.truth.back().push_back(seen[i].second);
    }
  }
  return views;
}

}  // namespace facedyn::reconstruct::testing
