#include "sim/sim_capture.h"

#include <chrono>
#include <cmath>
#include <filesystem>

#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh.h"
#include "sim/procedural_face.h"
#include "sim/skull_motion.h"

namespace facedyn::sim {
namespace {

Json RenderOptionsToJson(const RenderOptions& r) {
  return Json{{"skin_albedo", r.skin_albedo},
              {"marker_albedo", r.marker_albedo},
              {"background", r.background},
              {"ambient", r.ambient},
              {"gain", r.gain},
              {"read_noise_dn", r.read_noise_dn},
              {"shot_noise_gain", r.shot_noise_gain},
              {"blur_sigma_px", r.blur_sigma_px},
              {"motion_blur_samples", r.motion_blur_samples},
              {"supersample", r.supersample},
              {"seed", r.seed}};
}

}  // namespace

Status SimCaptureOptions::Check() const {
  FACEDYN_RETURN_IF_ERROR(performance.motion.Check());
  FACEDYN_RETURN_IF_ERROR(render.Check());
  if (!(lead_in_s >= performance.motion.ramp_in_s && lead_in_s <= 10)) {
    return InvalidArgumentError("sim.lead_in_s must be in [motion ramp-in " +
                                std::to_string(performance.motion.ramp_in_s) + " s, 10 s]");
  }
  return Status::Ok();
}

StatusOr<SimCaptureOptions> ParseSimCaptureOptions(const ConfigNode& node,
                                                   const std::string& base_dir) {
  FACEDYN_RETURN_IF_ERROR(
      node.CheckFields({"face", "expression", "motion", "platform_hz", "amplitude_mm", "lead_in_s",
                        "seed", "render", "faults", "markers", "markers_max_view_angle_deg"}));
  SimCaptureOptions options;
  FACEDYN_ASSIGN_OR_RETURN(options.face, node.GetOr<std::string>("face", "procedural"));
  if (options.face != "procedural" && !options.face.empty() && options.face[0] != '/') {
    options.face = (std::filesystem::path(base_dir) / options.face).lexically_normal().string();
  }
  FACEDYN_ASSIGN_OR_RETURN(options.markers, node.GetOr<std::string>("markers", ""));
  FACEDYN_ASSIGN_OR_RETURN(options.markers_max_view_angle_deg,
                           node.GetOr<double>("markers_max_view_angle_deg", 0.0));
  if (!(options.markers_max_view_angle_deg >= 0 && options.markers_max_view_angle_deg < 90)) {
    return node.Error("markers_max_view_angle_deg", "must be in [0, 90) degrees (0: no filter)");
  }
  if (!options.markers.empty() &&
      options.markers.find_first_not_of("0123456789") != std::string::npos &&
      options.markers[0] != '/') {
    options.markers =
        (std::filesystem::path(base_dir) / options.markers).lexically_normal().string();
  }
  FACEDYN_ASSIGN_OR_RETURN(options.performance.expression,
                           node.GetOr<std::string>("expression", "neutral"));
  FACEDYN_ASSIGN_OR_RETURN(const std::string motion, node.GetOr<std::string>("motion", "platform"));
  auto kind = ParseMotionKind(motion, &options.performance.motion.file);
  if (!kind.ok()) return node.Error("motion", kind.status().message());
  options.performance.motion.kind = *kind;
  FACEDYN_ASSIGN_OR_RETURN(options.performance.motion.platform_hz,
                           node.GetOr<double>("platform_hz", 8.0));
  FACEDYN_ASSIGN_OR_RETURN(options.performance.motion.amplitude_mm,
                           node.GetOr<double>("amplitude_mm", 2.0));
  FACEDYN_ASSIGN_OR_RETURN(options.lead_in_s, node.GetOr<double>("lead_in_s", 0.5));
  FACEDYN_ASSIGN_OR_RETURN(const int seed, node.GetOr<int>("seed", 1));
  options.performance.seed = static_cast<uint64_t>(seed);
  options.performance.motion.seed = static_cast<uint64_t>(seed);
  options.render.seed = static_cast<uint64_t>(seed);
  if (node.Has("render")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode render, node.Child("render"));
    FACEDYN_RETURN_IF_ERROR(render.CheckFields(
        {"skin_albedo", "marker_albedo", "background", "ambient", "gain", "read_noise_dn",
         "shot_noise_gain", "blur_sigma_px", "motion_blur_samples", "supersample"}));
    RenderOptions& r = options.render;
    FACEDYN_ASSIGN_OR_RETURN(r.skin_albedo, render.GetOr<double>("skin_albedo", r.skin_albedo));
    FACEDYN_ASSIGN_OR_RETURN(r.marker_albedo,
                             render.GetOr<double>("marker_albedo", r.marker_albedo));
    FACEDYN_ASSIGN_OR_RETURN(r.background, render.GetOr<double>("background", r.background));
    FACEDYN_ASSIGN_OR_RETURN(r.ambient, render.GetOr<double>("ambient", r.ambient));
    FACEDYN_ASSIGN_OR_RETURN(r.gain, render.GetOr<double>("gain", r.gain));
    FACEDYN_ASSIGN_OR_RETURN(r.read_noise_dn,
                             render.GetOr<double>("read_noise_dn", r.read_noise_dn));
    FACEDYN_ASSIGN_OR_RETURN(r.shot_noise_gain,
                             render.GetOr<double>("shot_noise_gain", r.shot_noise_gain));
    FACEDYN_ASSIGN_OR_RETURN(r.blur_sigma_px,
                             render.GetOr<double>("blur_sigma_px", r.blur_sigma_px));
    FACEDYN_ASSIGN_OR_RETURN(r.motion_blur_samples,
                             render.GetOr<int>("motion_blur_samples", r.motion_blur_samples));
    FACEDYN_ASSIGN_OR_RETURN(r.supersample, render.GetOr<int>("supersample", r.supersample));
    Status status = r.Check();
    if (!status.ok()) return render.Error(status.message());
  }
  if (node.Has("faults")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode faults, node.Child("faults"));
    for (const std::string& camera : faults.Keys()) {
      FACEDYN_ASSIGN_OR_RETURN(const ConfigNode entry, faults.Child(camera));
      FACEDYN_RETURN_IF_ERROR(
          entry.CheckFields({"drop", "duplicate", "late", "timestamp_offset_ns"}));
      SimCameraFaults f;
      for (const char* key : {"drop", "duplicate", "late"}) {
        FACEDYN_ASSIGN_OR_RETURN(const std::vector<int> list,
                                 entry.GetOr<std::vector<int>>(key, {}));
        std::set<int64_t>& target = std::string(key) == "drop"        ? f.drop_triggers
                                    : std::string(key) == "duplicate" ? f.duplicate_triggers
                                                                      : f.late_triggers;
        target.insert(list.begin(), list.end());
      }
      FACEDYN_ASSIGN_OR_RETURN(const int offset, entry.GetOr<int>("timestamp_offset_ns", 0));
      f.timestamp_offset_ns = offset;
      options.faults[camera] = f;
    }
  }
  Status status = options.Check();
  if (!status.ok()) return node.Error(status.message());
  return options;
}

Take TrimTake(const Take& take, int first_frame) {
  FACEDYN_CHECK(first_frame >= 0 && first_frame < take.frame_count(),
                "TrimTake: first_frame out of range");
  const int frames = take.frame_count() - first_frame;
  Take out;
  out.info = take.info;
  out.topology = take.topology;
  out.positions = take.positions;
  out.positions.positions = take.positions.positions.rightCols(frames);
  for (const auto& [name, cache] : take.channels) {
    PointCache trimmed = cache;
    trimmed.positions = cache.positions.rightCols(frames);
    out.channels[name] = trimmed;
  }
  out.world_from_skull.assign(take.world_from_skull.begin() + first_frame,
                              take.world_from_skull.end());
  if (!take.skull_from_jaw.empty())
    out.skull_from_jaw.assign(take.skull_from_jaw.begin() + first_frame, take.skull_from_jaw.end());
  out.SetUniformTimes();
  // Times are from the first frame kept: the held part starts first_frame frames earlier.
  if (out.info.hold_start_s && out.info.fps > 0) {
    out.info.hold_start_s = std::max(0.0, *out.info.hold_start_s - first_frame / out.info.fps);
  }
  return out;
}

std::vector<Marker> MarkersSeenByEveryCamera(const FaceRig& rig,
                                             const std::vector<capture::CameraModel>& cameras,
                                             double max_angle_deg) {
  const Eigen::Matrix3Xd& skin = rig.neutral.positions_mm;
  const Eigen::Matrix3Xd normals = VertexNormals(rig.neutral, skin);
  // Outward: the skin's normals point away from the skull's centre on average.
  const Eigen::Vector3d centre = skin.rowwise().mean();
  double outward = 0.0;
  for (int v = 0; v < skin.cols(); ++v) outward += normals.col(v).dot(skin.col(v) - centre);
  const double sign = outward >= 0 ? 1.0 : -1.0;
  const double min_cos = std::cos(max_angle_deg * M_PI / 180.0);
  std::vector<Marker> seen;
  for (const Marker& marker : rig.markers) {
    const Eigen::Vector3d p = marker.point.Evaluate(skin);
    const Eigen::Vector3d n = sign * marker.point.Evaluate(normals).normalized();
    bool all = true;
    for (const capture::CameraModel& camera : cameras) {
      const Eigen::Vector3d centre_in_world = camera.cam_from_world.Inverse().translation();
      const Eigen::Vector3d to_camera = (centre_in_world - p).normalized();
      Eigen::Vector2d pixel;
      all = all && to_camera.dot(n) >= min_cos && camera.Project(p, &pixel) && pixel.x() >= 0 &&
            pixel.y() >= 0 && pixel.x() <= camera.width_px - 1 && pixel.y() <= camera.height_px - 1;
    }
    if (all) seen.push_back(marker);
  }
  return seen;
}

StatusOr<std::vector<Marker>> PaintedMarkers(const FaceRig& rig, const SimCaptureOptions& options,
                                             const std::vector<capture::CameraModel>& cameras) {
  FaceRig painted = rig;
  if (options.markers_max_view_angle_deg > 0) {
    painted.markers = MarkersSeenByEveryCamera(rig, cameras, options.markers_max_view_angle_deg);
  }
  if (!options.markers.empty()) {
    FACEDYN_ASSIGN_OR_RETURN(painted.markers,
                             SelectMarkerLayout(painted, options.markers, "sim.markers"));
  }
  return painted.markers;
}

Take TakeInSkullFrame(const Take& take) {
  Take out = take;
  for (int f = 0; f < take.frame_count(); ++f) {
    const Rigid3 skull_from_world = take.world_from_skull[f].Inverse();
    out.positions.Frame(f) = skull_from_world.Apply(take.FramePositions(f)).cast<float>();
    for (auto& [name, channel] : out.channels) {
      if (name != "quasistatic") continue;
      channel.Frame(f) = skull_from_world.Apply(channel.Frame(f).cast<double>()).cast<float>();
    }
  }
  for (Rigid3& pose : out.world_from_skull) pose = Rigid3();
  return out;
}

StatusOr<SimulatedStage> PrepareSimulatedStage(const SimCaptureOptions& options,
                                               const std::vector<capture::CameraModel>& cameras,
                                               double fps, int64_t triggers, double platform_hz,
                                               capture::CameraMount mount) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  SimulatedStage stage;
  if (options.face == "procedural") {
    FACEDYN_ASSIGN_OR_RETURN(stage.rig, MakeProceduralFace(ProceduralFaceOptions()));
  } else {
    FACEDYN_ASSIGN_OR_RETURN(stage.rig, LoadFaceRig(options.face));
  }
  FACEDYN_ASSIGN_OR_RETURN(stage.rig.markers, PaintedMarkers(stage.rig, options, cameras));
  PerformanceOptions performance = options.performance;
  if (platform_hz > 0) performance.motion.platform_hz = platform_hz;
  stage.platform_hz = performance.motion.platform_hz;
  performance.fps = fps;
  const int lead_frames = static_cast<int>(std::ceil(options.lead_in_s * fps));
  // One extra frame after the last trigger, for motion blur across the last exposure.
  performance.seconds = (lead_frames + triggers + 1) / fps;
  const auto start = std::chrono::steady_clock::now();
  FACEDYN_ASSIGN_OR_RETURN(Take simulated, SimulatePerformance(stage.rig, performance));
  stage.simulate_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (simulated.frame_count() < lead_frames + triggers) {
    return InternalError("the simulated take has " + std::to_string(simulated.frame_count()) +
                         " frames, fewer than the " + std::to_string(lead_frames + triggers) +
                         " needed");
  }
  if (const auto held = HeldExpressionStartS(performance)) {
    stage.hold_start_s = std::max(0.0, *held - lead_frames / fps);
  }
  Take trimmed = TrimTake(simulated, lead_frames);
  trimmed.info.metadata["capture_lead_in_frames"] = lead_frames;
  stage.take = std::make_shared<const Take>(std::move(trimmed));
  stage.camera_take = mount == capture::CameraMount::kHead
                          ? std::make_shared<const Take>(TakeInSkullFrame(*stage.take))
                          : stage.take;
  stage.renderer = std::make_shared<const FaceRenderer>(stage.rig, options.render);
  for (size_t k = 0; k < cameras.size(); ++k) {
    SimCameraFaults faults;
    if (auto it = options.faults.find(cameras[k].name); it != options.faults.end())
      faults = it->second;
    stage.cameras.push_back(std::make_unique<SimCamera>(static_cast<int>(k), cameras[k],
                                                        stage.renderer, stage.camera_take, faults));
  }
  return stage;
}

Status WriteGroundTruth(const SimulatedStage& stage, const SimCaptureOptions& options,
                        const std::vector<capture::CameraModel>& cameras,
                        const std::string& take_dir) {
  const std::string dir = JoinPath(take_dir, "ground_truth");
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  FACEDYN_RETURN_IF_ERROR(SaveTake(*stage.take, JoinPath(dir, "take")));
  FACEDYN_RETURN_IF_ERROR(capture::WriteCameraModels(JoinPath(dir, "cameras.yaml"), cameras));
  FACEDYN_RETURN_IF_ERROR(SaveFaceRig(stage.rig, JoinPath(dir, "face")));
  Json faults = Json::object();
  for (const auto& [camera, f] : options.faults) {
    faults[camera] = {
        {"drop", std::vector<int64_t>(f.drop_triggers.begin(), f.drop_triggers.end())},
        {"duplicate",
         std::vector<int64_t>(f.duplicate_triggers.begin(), f.duplicate_triggers.end())},
        {"late", std::vector<int64_t>(f.late_triggers.begin(), f.late_triggers.end())},
        {"timestamp_offset_ns", f.timestamp_offset_ns}};
  }
  const Json info{{"render", RenderOptionsToJson(options.render)},
                  {"platform_hz", stage.platform_hz},
                  {"expression", options.performance.expression},
                  {"motion", MotionKindName(options.performance.motion.kind)},
                  {"amplitude_mm", options.performance.motion.amplitude_mm},
                  {"lead_in_s", options.lead_in_s},
                  {"seed", options.performance.seed},
                  {"faults", faults},
                  {"note",
                   "trigger k shows take frame k (t = k / fps); marker centres: face/markers.csv "
                   "on take positions"}};
  return WriteJsonFile(JoinPath(dir, "render.json"), info);
}

}  // namespace facedyn::sim
