#include "sim/performance.h"

#include <chrono>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/progress.h"
#include "sim/expression_curve.h"
#include "sim/expressions.h"

namespace facedyn::sim {
namespace {

// Fade-in of a held expression (MakeHeldExpression's ramp_s).
constexpr double kExpressionRamp_s = 0.3;

// skull_from_jaw: rotation by `angle` about the rig's hinge axis through its pivot.
Rigid3 SkullFromJaw(const FaceRig& rig, double angle_rad) {
  const Eigen::Quaterniond q(Eigen::AngleAxisd(angle_rad, rig.jaw.axis_in_skull.normalized()));
  return Rigid3(q, rig.jaw.pivot_in_skull - q * rig.jaw.pivot_in_skull);
}

Json TissueJson(const physics::TissueOptions& t) {
  return {{"layers", t.layers},
          {"poisson_ratio", t.poisson_ratio},
          {"density_kg_per_mm3", t.density_kg_per_mm3},
          {"fundamental_hz", t.fundamental_hz},
          {"damping_ratio", t.damping_ratio},
          {"mass_damping_share", t.mass_damping_share},
          {"muscle_hz", t.muscle_hz},
          {"activation_full_mm", t.activation_full_mm},
          {"max_step_s", t.max_step_s}};
}

Json MotionJson(const MotionOptions& m) {
  Json json = {{"kind", MotionKindName(m.kind)}, {"seed", m.seed}, {"ramp_in_s", m.ramp_in_s}};
  switch (m.kind) {
    case MotionKind::kPlatform:
      json.update({{"platform_hz", m.platform_hz}, {"amplitude_mm", m.amplitude_mm},
                   {"body_resonance_hz", m.body_resonance_hz}, {"body_damping_ratio", m.body_damping_ratio},
                   {"pitch_rad_per_g", m.pitch_rad_per_g}, {"sway_mm", m.sway_mm},
                   {"sway_min_hz", m.sway_min_hz}, {"sway_max_hz", m.sway_max_hz}});
      break;
    case MotionKind::kWalk:
      json.update({{"walk_step_hz", m.walk_step_hz}, {"walk_speed_mm_per_s", m.walk_speed_mm_per_s},
                   {"walk_vertical_mm", m.walk_vertical_mm}, {"walk_lateral_mm", m.walk_lateral_mm},
                   {"walk_heel_strike_g", m.walk_heel_strike_g}});
      break;
    case MotionKind::kRun:
      json.update({{"run_step_hz", m.run_step_hz}, {"run_speed_mm_per_s", m.run_speed_mm_per_s},
                   {"run_flight_s", m.run_flight_s}, {"run_impact_g", m.run_impact_g},
                   {"run_impact_s", m.run_impact_s}});
      break;
    case MotionKind::kJump:
      json.update({{"jump_period_s", m.jump_period_s}, {"jump_flight_s", m.jump_flight_s},
                   {"jump_impact_g", m.jump_impact_g}, {"jump_impact_s", m.jump_impact_s}});
      break;
    case MotionKind::kNod:
    case MotionKind::kShake:
      json.update({{"head_motion_hz", m.head_motion_hz}, {"head_motion_deg", m.head_motion_deg},
                   {"neck_pivot_y_mm", m.neck_pivot_y_mm}, {"neck_pivot_z_mm", m.neck_pivot_z_mm}});
      break;
    case MotionKind::kSway:
      json.update({{"head_motion_hz", m.head_motion_hz}, {"head_sway_mm", m.head_sway_mm}});
      break;
    case MotionKind::kTurnWalk:
      json.update({{"walk_step_hz", m.walk_step_hz},
                   {"walk_speed_mm_per_s", m.walk_speed_mm_per_s},
                   {"head_motion_hz", m.head_motion_hz},
                   {"head_motion_deg", m.head_motion_deg},
                   {"neck_pivot_y_mm", m.neck_pivot_y_mm},
                   {"neck_pivot_z_mm", m.neck_pivot_z_mm}});
      break;
    case MotionKind::kLieBack:
      json.update({{"lie_back_deg", m.lie_back_deg}, {"lie_back_s", m.lie_back_s}});
      break;
    case MotionKind::kFile:
      json["file"] = m.file;
      break;
    case MotionKind::kNone:
      break;
  }
  return json;
}

}  // namespace

Status PerformanceOptions::Check() const {
  if (!(seconds > 0 && seconds <= 600)) return InvalidArgumentError(fmt::format("seconds must be in (0, 600], got {}", seconds));
  if (!(fps >= 1 && fps <= 2000)) return InvalidArgumentError(fmt::format("fps must be in [1, 2000], got {}", fps));
  if (expression.empty()) return InvalidArgumentError("expression must not be empty");
  FACEDYN_RETURN_IF_ERROR(motion.Check());
  return tissue.Check();
}

std::optional<double> HeldExpressionStartS(const PerformanceOptions& options) {
  if (options.expression == "speech" || options.expression == "range_of_motion") {
    return std::nullopt;
  }
  // The expression forms over kExpressionRamp_s and the motion fades in over its ramp_in_s;
  // the skin's transient from both then decays. Before that a held-expression target (moving
  // average, platform fit) is wrong by up to 0.5 mm at the mouth corners (smile, 8 Hz), so
  // training and evaluation start after a fixed margin (core/take.h kHeldExpressionSettleS):
  // the take's metadata is what a capture would know, never the tissue's true parameters.
  const double motion_ramp_s =
      (options.motion.kind == MotionKind::kNone || options.motion.kind == MotionKind::kFile)
          ? 0.0
          : options.motion.ramp_in_s;
  return std::max(kExpressionRamp_s, motion_ramp_s) + kHeldExpressionSettleS;
}

StatusOr<Take> SimulatePerformance(const FaceRig& rig, const PerformanceOptions& options,
                                   PerformanceSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_RETURN_IF_ERROR(rig.Validate());

  // Expression over time, and the reference expression the dynamics are linearised about.
  std::unique_ptr<ExpressionCurve> curve;
  Eigen::VectorXd reference_weights;
  if (options.expression == "speech" || options.expression == "range_of_motion") {
    const bool speech = options.expression == "speech";
    FACEDYN_ASSIGN_OR_RETURN(const std::vector<Eigen::VectorXd> keys,
                             speech ? DialogueVisemes(rig) : RangeOfMotionPoses(rig));
    reference_weights = Eigen::VectorXd::Zero(keys.front().size());
    for (const auto& k : keys) reference_weights += k / double(keys.size());
    curve = speech ? MakeSpeechSequence(keys, 4.5, options.seed)
                   : MakeScriptedSequence(keys, 3.0, options.seed);
  } else {
    FACEDYN_ASSIGN_OR_RETURN(reference_weights, ExpressionWeights(rig, options.expression));
    curve = MakeHeldExpression(reference_weights, kExpressionRamp_s, 0.02, options.seed);
  }
  FACEDYN_ASSIGN_OR_RETURN(std::unique_ptr<SkullMotion> motion, MakeSkullMotion(options.motion));
  // An explicit material (a twin's) is built in directly, without the calibration's eigensolve.
  FACEDYN_ASSIGN_OR_RETURN(std::unique_ptr<physics::SoftTissueModel> model,
                           options.material ? physics::SoftTissueModel::Create(rig, options.tissue, *options.material)
                                            : physics::SoftTissueModel::Create(rig, options.tissue));

  const int frames = static_cast<int>(std::lround(options.seconds * options.fps));
  const double frame_dt = 1.0 / options.fps;
  const int substeps = std::max(1, static_cast<int>(std::ceil(frame_dt / options.tissue.max_step_s - 1e-9)));
  const double dt = frame_dt / substeps;
  FACEDYN_ASSIGN_OR_RETURN(const physics::ReferenceSummary reference,
                           model->SetReference(reference_weights, JawAngleRad(rig, reference_weights), dt));
  if (reference.inverted_elements > 0) {
    spdlog::warn("expression '{}' turns {} tetrahedra inside out; their stiffness uses |volume|",
                 options.expression, reference.inverted_elements);
  }
  // Expression velocity and acceleration by central differences of the (smooth) curve; the
  // step is far below the curve's time scales (drift < 1 Hz, syllables ~5 Hz).
  constexpr double kH = 1e-3;
  auto forcing_at = [&](double t) {
    physics::TissueForcing forcing;
    forcing.kinematics = motion->Kinematics(t);
    forcing.weights = curve->Weights(t);
    forcing.jaw_angle_rad = JawAngleRad(rig, forcing.weights);
    const Eigen::VectorXd before = curve->Weights(t - kH), after = curve->Weights(t + kH);
    forcing.weight_accelerations = (after - 2 * forcing.weights + before) / (kH * kH);
    const double jaw_before = JawAngleRad(rig, before), jaw_after = JawAngleRad(rig, after);
    forcing.jaw_angle_velocity = (jaw_after - jaw_before) / (2 * kH);
    forcing.jaw_angle_acceleration = (jaw_after - 2 * forcing.jaw_angle_rad + jaw_before) / (kH * kH);
    return forcing;
  };

  Take take;
  take.info.fps = options.fps;
  take.info.subject = rig.name;
  take.info.expression = options.expression;
  take.info.motion = MotionKindName(options.motion.kind);
  if (options.motion.kind == MotionKind::kPlatform) take.info.platform_hz = options.motion.platform_hz;
  take.info.source = "sim perform";
  take.topology = rig.neutral;
  const int v = rig.vertex_count();
  auto make_cache = [&] {
    PointCache cache;
    cache.vertex_count = v;
    cache.positions.resize(3 * v, frames);
    return cache;
  };
  take.positions = make_cache();
  PointCache quasistatic = make_cache();
  PointCache offset = make_cache();

  Progress progress("simulate " + options.expression + "/" + take.info.motion, frames);
  physics::TissueForcing forcing = forcing_at(0.0);
  model->Reset(forcing);
  for (int f = 0; f < frames; ++f) {
    const double t = f * frame_dt;
    if (f > 0) {
      for (int s = 1; s <= substeps; ++s) {
        forcing = forcing_at((f - 1) * frame_dt + s * dt);
        model->Step(forcing);
      }
    }
    const Rigid3& world_from_skull = forcing.kinematics.world_from_skull;
    const Eigen::Matrix3Xd dynamic_in_skull = model->DynamicSkin();
    const Eigen::Matrix3Xd quasistatic_in_skull = model->QuasistaticSkin(forcing);
    take.positions.Frame(f) = world_from_skull.Apply(dynamic_in_skull).cast<float>();
    quasistatic.Frame(f) = world_from_skull.Apply(quasistatic_in_skull).cast<float>();
    offset.Frame(f) = (dynamic_in_skull - quasistatic_in_skull).cast<float>();
    take.world_from_skull.push_back(world_from_skull);
    take.skull_from_jaw.push_back(SkullFromJaw(rig, forcing.jaw_angle_rad));
    take.time_s.push_back(t);
    progress.Advance();
  }
  progress.Finish();
  take.channels["quasistatic"] = std::move(quasistatic);
  take.channels["dynamic_offset"] = std::move(offset);
  take.info.hold_start_s = HeldExpressionStartS(options);

  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  take.info.metadata = {
      {"generator", "facedyn sim perform"},
      {"face", rig.name},
      {"expression", options.expression},
      {"seconds", options.seconds},
      {"fps", options.fps},
      {"seed", options.seed},
      {"motion", MotionJson(options.motion)},
      {"tissue", TissueJson(options.tissue)},
      {"material", options.material ? "explicit" : "calibrated"},
      {"youngs_modulus_kpa", model->youngs_modulus_kpa()},
      {"rayleigh_mass_per_s", model->rayleigh_mass()},
      {"rayleigh_stiffness_s", model->rayleigh_stiffness()},
      {"substeps_per_frame", substeps},
      {"tet_count", model->shell().tets.cols()},
      {"free_dofs", model->free_dof_count()},
      {"dynamic_offset_frame", "skull"}};
  if (summary) {
    summary->reference = reference;
    summary->youngs_modulus_kpa = model->youngs_modulus_kpa();
    summary->substeps_per_frame = substeps;
    summary->simulate_s = seconds;
  }
  return take;
}

StatusOr<std::map<std::string, double>> PeakOffsetByRegionMm(const FaceRig& rig, const Take& take,
                                                             double skip_first_s) {
  auto it = take.channels.find("dynamic_offset");
  if (it == take.channels.end()) return FailedPreconditionError("take has no dynamic_offset channel");
  if (take.vertex_count() != rig.vertex_count()) {
    return FailedPreconditionError("take and face rig have different vertex counts");
  }
  const PointCache& offset = it->second;
  const int first = std::min(take.frame_count(), static_cast<int>(std::ceil(skip_first_s * take.info.fps)));
  Eigen::VectorXd peak = Eigen::VectorXd::Zero(take.vertex_count());
  for (int f = first; f < take.frame_count(); ++f) {
    peak = peak.cwiseMax(offset.Frame(f).colwise().norm().transpose().cast<double>());
  }
  std::map<std::string, double> result;
  result["face"] = peak.size() ? peak.maxCoeff() : 0.0;
  for (const auto& [name, vertices] : rig.regions) {
    double value = 0;
    for (int v : vertices) value = std::max(value, peak[v]);
    result[name] = value;
  }
  return result;
}

}  // namespace facedyn::sim
