#include "dynamics/feature_spec.h"

#include <cmath>
#include <cstdio>

namespace facedyn::dynamics {

namespace {

std::string Hex64(uint64_t value) {
  char buffer[17];
  std::snprintf(buffer, sizeof(buffer), "%016llx", static_cast<unsigned long long>(value));
  return buffer;
}

std::string FormatVector(const Eigen::Vector3d& v) {
  char buffer[96];
  std::snprintf(buffer, sizeof(buffer), "(%.4f, %.4f, %.4f)", v.x(), v.y(), v.z());
  return buffer;
}

}  // namespace

uint64_t HashSurfacePoints(const std::vector<SurfacePoint>& points) {
  uint64_t hash = 1469598103934665603ull;
  auto mix = [&hash](const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t k = 0; k < bytes; ++k) {
      hash ^= p[k];
      hash *= 1099511628211ull;
    }
  };
  for (const SurfacePoint& point : points) {
    for (int k = 0; k < 3; ++k) {
      const int32_t vertex = point.vertices[k];
      const double weight = point.weights[k];
      mix(&vertex, sizeof(vertex));
      mix(&weight, sizeof(weight));
    }
  }
  return hash;
}

FeatureSpec FeatureSpec::ForRig(const FaceRig& rig, double fps, double window_s) {
  FeatureSpec spec;
  spec.features.fps = fps;
  spec.features.window_s = window_s;
  spec.landmarks = rig.skull_landmarks;
  spec.sample_count = static_cast<int>(rig.skin_samples.size());
  spec.samples_hash = HashSurfacePoints(rig.skin_samples);
  return spec;
}

Status FeatureSpec::Check() const {
  FACEDYN_RETURN_IF_ERROR(features.Check());
  if (landmarks.empty()) return InvalidArgumentError("landmarks: at least one skull landmark");
  if (sample_count < 1) return InvalidArgumentError("sample_count must be >= 1");
  return Status::Ok();
}

Status FeatureSpec::CheckCompatible(const Take& take, const FaceRig& rig) const {
  const double fps = features.fps;
  if (!(std::abs(take.info.fps - fps) <= 1e-6 * fps)) {
    return FailedPreconditionError("fps: the model was trained at " + std::to_string(fps) +
                                   " fps, the take is at " + std::to_string(take.info.fps) +
                                   " fps (feature windows are counted in frames)");
  }
  if (rig.vertex_count() != take.vertex_count()) {
    return FailedPreconditionError("vertex_count: the rig has " +
                                   std::to_string(rig.vertex_count()) + " vertices, the take " +
                                   std::to_string(take.vertex_count()));
  }
  if (rig.skull_landmarks.size() != landmarks.size()) {
    return FailedPreconditionError("skull_landmarks: the model has " +
                                   std::to_string(landmarks.size()) + " landmarks, the rig has " +
                                   std::to_string(rig.skull_landmarks.size()));
  }
  for (size_t k = 0; k < landmarks.size(); ++k) {
    const Eigen::Vector3d& a = landmarks[k].position_in_skull;
    const Eigen::Vector3d& b = rig.skull_landmarks[k].position_in_skull;
    if ((a - b).norm() > 1e-6) {
      return FailedPreconditionError("skull_landmarks: landmark " + std::to_string(k) + " ('" +
                                     landmarks[k].name + "') is at " + FormatVector(a) +
                                     " mm in the model and " + FormatVector(b) + " mm in the rig");
    }
  }
  if (static_cast<int>(rig.skin_samples.size()) != sample_count) {
    return FailedPreconditionError("skin_samples: the model has " + std::to_string(sample_count) +
                                   " samples, the rig has " +
                                   std::to_string(rig.skin_samples.size()));
  }
  const uint64_t hash = HashSurfacePoints(rig.skin_samples);
  if (hash != samples_hash) {
    return FailedPreconditionError("skin_samples: same count (" + std::to_string(sample_count) +
                                   ") but different sample definitions (hash " +
                                   Hex64(samples_hash) + " in the model, " + Hex64(hash) +
                                   " in the rig)");
  }
  return Status::Ok();
}

Json FeatureSpec::ToJson() const {
  Json json;
  json["fps"] = features.fps;
  json["window_s"] = features.window_s;
  json["window_frames"] = features.window_frames();
  json["stretch_step_mm"] = features.stretch_step_mm;
  Json landmark_list = Json::array();
  for (const SkullLandmark& landmark : landmarks) {
    landmark_list.push_back({{"name", landmark.name},
                             {"position_in_skull_mm",
                              {landmark.position_in_skull.x(), landmark.position_in_skull.y(),
                               landmark.position_in_skull.z()}}});
  }
  json["landmarks"] = landmark_list;
  json["sample_count"] = sample_count;
  json["samples_hash"] = Hex64(samples_hash);
  return json;
}

StatusOr<FeatureSpec> FeatureSpec::FromJson(const Json& json) {
  FeatureSpec spec;
  try {
    spec.features.fps = json.at("fps").get<double>();
    spec.features.window_s = json.at("window_s").get<double>();
    spec.features.stretch_step_mm = json.at("stretch_step_mm").get<double>();
    for (const Json& landmark : json.at("landmarks")) {
      const Json& p = landmark.at("position_in_skull_mm");
      spec.landmarks.push_back(
          {landmark.at("name").get<std::string>(),
           Eigen::Vector3d(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>())});
    }
    spec.sample_count = json.at("sample_count").get<int>();
    spec.samples_hash = std::stoull(json.at("samples_hash").get<std::string>(), nullptr, 16);
    if (json.at("window_frames").get<int>() != spec.features.window_frames()) {
      return DataLossError("window_frames " + json.at("window_frames").dump() +
                           " disagrees with fps and window_s");
    }
  } catch (const std::exception& e) {
    return DataLossError(std::string("bad feature spec: ") + e.what());
  }
  if (Status status = spec.Check(); !status.ok()) {
    return DataLossError("bad feature spec: " + status.message());
  }
  return spec;
}

}  // namespace facedyn::dynamics
