// skull_pose_bench: how much of the stable markers' jiggle leaks into the estimated skull pose
// (issue 20), per platform frequency and head motion, printed as JSON.
//
// Every take is simulated (sim/performance.h: the procedural face, neutral, default tissue), its
// markers are read off the simulated skin (the positions a perfect reconstruction would
// triangulate), Gaussian noise of --noise-mm per axis is added, and the skull pose is estimated
// per frame by reconstruct/skull_pose.h with each of the variants below. The error against the
// simulator's world_from_skull is reported at the skull origin (mm) and as a rotation angle
// (degrees), RMS and max over the frames after the motion's fade-in (--skip-s). The simulator
// is the truth here only: no variant reads it.
//
// Variants (SkullPoseOptions): "rigid" (a plain robust rigid fit, equal weights, no
// deflection); "deflection_wP" (prior weights (t_min / t)^P and one deflection d per frame
// moving every marker along it; w2 is round 1's estimator); "..._normals" (then the
// translation re-fitted to the markers' normal components only); "static..." and "ritz..."
// (the tissue model's deflection shapes, physics/inertial_deflection.h, in place of the t^2
// law). The default is ritz2_w4_normals, per frame; "default_take_reference" is the default
// estimator over the whole take with the take-level reference (SkullPoseEstimator::EstimateTake,
// as the pipeline runs it: the stable markers' reference re-estimated from the take).
//
// The simulated subject is the default tissue unless --subject-hz / --subject-damping say
// otherwise; --heterogeneous makes its stable regions differ in stiffness (forehead x1.6, nose
// bridge x0.6, temples x1.3), which the tissue model's shapes (one modulus) do not know.
//
// Also per take, a diagnostic of the truth: the share of the stable markers' true dynamic offset
// (skull frame) that is normal to the skin, and its RMS.
//
//   skull_pose_bench [--noise-mm S] [--seconds S] [--skip-s S] [--subject-hz F]
//                    [--subject-damping Z] [--heterogeneous] [--seed N]

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "bench/bench_flags.h"
#include "core/json_io.h"
#include "core/log.h"
#include "core/mesh.h"
#include "physics/inertial_deflection.h"
#include "physics/soft_tissue.h"
#include "physics/twin.h"
#include "reconstruct/skull_pose.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace {

using facedyn::Json;

struct TakeSpec {
  std::string name;
  facedyn::sim::MotionOptions motion;
};

std::vector<TakeSpec> Specs(uint64_t seed) {
  std::vector<TakeSpec> specs;
  for (double hz : {6.0, 8.5, 11.0}) {
    facedyn::sim::MotionOptions motion;
    motion.kind = facedyn::sim::MotionKind::kPlatform;
    motion.platform_hz = hz;
    motion.seed = seed;
    specs.push_back({fmt::format("platform {:g} Hz", hz), motion});
  }
  for (auto kind : {facedyn::sim::MotionKind::kWalk, facedyn::sim::MotionKind::kRun}) {
    facedyn::sim::MotionOptions motion;
    motion.kind = kind;
    motion.seed = seed;
    specs.push_back({std::string(facedyn::sim::MotionKindName(kind)) + " in place", motion});
  }
  for (auto& spec : specs) {
    // In place: forward speed changes nothing for the tissue (dynamics_study.h).
    spec.motion.walk_speed_mm_per_s = 0;
    spec.motion.run_speed_mm_per_s = 0;
  }
  return specs;
}

// Accumulated per frame by Add (sums of squares until ToJson divides by the frame count).
struct PoseError {
  double origin_rms_mm = 0, origin_max_mm = 0, rotation_rms_deg = 0, rotation_max_deg = 0;
  void Add(const facedyn::Rigid3& truth, const facedyn::Rigid3& estimate) {
    const facedyn::Rigid3 d = truth.Inverse() * estimate;
    const double t = d.translation().norm(), r = d.AngleRad() * 180.0 / M_PI;
    origin_rms_mm += t * t;
    rotation_rms_deg += r * r;
    origin_max_mm = std::max(origin_max_mm, t);
    rotation_max_deg = std::max(rotation_max_deg, r);
  }
  facedyn::Json ToJson(int frames) const {
    return {{"origin_rms_mm", std::sqrt(origin_rms_mm / frames)},
            {"origin_max_mm", origin_max_mm},
            {"rotation_rms_deg", std::sqrt(rotation_rms_deg / frames)},
            {"rotation_max_deg", rotation_max_deg}};
  }
};

}  // namespace

int main(int argc, char** argv) {
  using namespace facedyn;
  double noise_mm = 0.0, seconds = 2.0, skip_s = 0.5;
  uint64_t seed = 1;
  // The simulated subject's tissue (the estimators are never told it).
  double subject_hz = physics::TissueOptions{}.fundamental_hz;
  double subject_damping = physics::TissueOptions{}.damping_ratio;
  // A subject whose stable regions differ in stiffness (the tissue model's shapes assume one
  // modulus everywhere): forehead x1.6, nose bridge x0.6, temples x1.3, the rest x1.
  bool heterogeneous = false;
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    auto next = [&]() -> const char* {
      if (k + 1 >= argc) {
        std::fprintf(stderr, "skull_pose_bench: %s needs a value\n", arg.c_str());
        std::exit(2);
      }
      return argv[++k];
    };
    if (arg == "--noise-mm") {
      noise_mm = bench::FlagNumber("skull_pose_bench", arg, next());
    } else if (arg == "--seconds") {
      seconds = bench::FlagNumber("skull_pose_bench", arg, next());
    } else if (arg == "--skip-s") {
      skip_s = bench::FlagNumber("skull_pose_bench", arg, next());
    } else if (arg == "--subject-hz") {
      subject_hz = bench::FlagNumber("skull_pose_bench", arg, next());
    } else if (arg == "--subject-damping") {
      subject_damping = bench::FlagNumber("skull_pose_bench", arg, next());
    } else if (arg == "--heterogeneous") {
      heterogeneous = true;
    } else if (arg == "--seed") {
      seed = static_cast<uint64_t>(bench::FlagInteger("skull_pose_bench", arg, next()));
    } else {
      std::fprintf(
          stderr,
          "usage: skull_pose_bench [--noise-mm S] [--seconds S] [--skip-s S] [--subject-hz F]\n"
          "                        [--subject-damping Z] [--heterogeneous] [--seed N]\n");
      return 2;
    }
  }
  if (!(noise_mm >= 0) || !(seconds >= 1) || !(skip_s >= 0) || skip_s >= seconds) {
    std::fprintf(stderr, "skull_pose_bench: need --noise-mm >= 0, --seconds >= 1, 0 <= --skip-s < --seconds\n");
    return 2;
  }
  InitLogging(Verbosity::kQuiet);
  const FaceRig face = sim::MakeProceduralFace(sim::ProceduralFaceOptions()).value();
  struct Variant {
    std::string name;
    reconstruct::SkullPoseOptions options;
  };
  std::vector<Variant> variants;
  auto add = [&](const std::string& name, double power, bool deflection, bool normals) {
    Variant v;
    v.name = name;
    v.options.thickness_prior = power > 0;
    v.options.thickness_weight_power = power > 0 ? power : 2.0;
    v.options.deflection_model = deflection;
    v.options.translation_from_normals = normals;
    v.options.deflection_shape = reconstruct::DeflectionShape::kThicknessSquared;
    variants.push_back(v);
  };
  add("rigid", 0, false, false);
  add("deflection_w2", 2, true, false);  // the estimator of round 1
  add("deflection_w2_normals", 2, true, true);
  add("deflection_w4", 4, true, false);
  add("deflection_w4_normals", 4, true, true);  // the default before the tissue model
  add("deflection_w6_normals", 6, true, true);
  add("deflection_w8_normals", 8, true, true);
  // The tissue model's deflection shapes in place of the t^2 law (default tissue options:
  // shapes only, no subject parameter), each basis computed once.
  std::map<std::pair<bool, int>, Eigen::MatrixXd> bases;
  auto add_basis = [&](const std::string& name, bool angular, double power, bool normals,
                       int blocks = 1) {
    Eigen::MatrixXd& basis = bases[{angular, blocks}];
    if (basis.size() == 0) {
      physics::InertialDeflectionOptions deflection;
      deflection.angular = angular;
      deflection.krylov_blocks = blocks;
      auto computed = physics::MarkerInertialDeflectionBasis(face, deflection);
      if (!computed.ok()) {
        std::fprintf(stderr, "skull_pose_bench: %s\n", computed.status().message().c_str());
        std::exit(1);
      }
      basis = std::move(*computed);
    }
    add(name, power, true, normals);
    variants.back().options.deflection_basis = basis;
  };
  // "static3": the static deflection under the three uniform loads; "static6": and the three
  // angular ones; "ritzK": K load-dependent Ritz blocks of the three uniform loads. The default
  // (SkullPoseOptions, DeflectionShape::kTissueModel) is ritz2_w4_normals.
  add_basis("static3_w4_normals", false, 4, true);
  add_basis("static6_w4_normals", true, 4, true);
  add_basis("ritz2_w4", false, 4, false, 2);
  add_basis("ritz2_w2_normals", false, 2, true, 2);
  add_basis("ritz2_w3_normals", false, 3, true, 2);
  add_basis("ritz2_w4_normals", false, 4, true, 2);
  // ..._joint: the rotation fitted jointly with the shapes too (rotation_from_thickness_law off).
  add_basis("ritz2_w4_normals_joint", false, 4, true, 2);
  variants.back().options.rotation_from_thickness_law = false;
  add_basis("static3_w4_normals_joint", false, 4, true, 1);
  variants.back().options.rotation_from_thickness_law = false;
  add_basis("ritz2_w6_normals", false, 6, true, 2);
  add_basis("ritz3_w4_normals", false, 4, true, 3);
  std::vector<reconstruct::SkullPoseEstimator> estimators;
  for (const Variant& v : variants) estimators.emplace_back(face, v.options);
  const std::vector<int>& stable = estimators.front().stable_markers();
  const Eigen::Matrix3Xd normals = VertexNormals(face.neutral, face.neutral.positions_mm);

  std::optional<physics::TissueMaterial> subject_material;
  if (heterogeneous) {
    physics::TissueOptions tissue;
    tissue.fundamental_hz = subject_hz;
    tissue.damping_ratio = subject_damping;
    auto model = physics::SoftTissueModel::Create(face, tissue);
    const std::vector<physics::StiffnessGroup> groups = {{"forehead", {"forehead"}},
                                                         {"nose_bridge", {"nose_bridge"}},
                                                         {"temples", {"temples"}},
                                                         {"rest", {}}};
    auto tet_group = model.ok() ? physics::TetStiffnessGroups(face, (*model)->shell(), groups)
                                : StatusOr<Eigen::VectorXi>(model.status());
    if (!tet_group.ok()) {
      std::fprintf(stderr, "skull_pose_bench: %s\n", tet_group.status().message().c_str());
      return 1;
    }
    const double scale[] = {1.6, 0.6, 1.3, 1.0};
    subject_material = (*model)->material();
    subject_material->tet_stiffness_scale.resize(tet_group->size());
    for (Eigen::Index e = 0; e < tet_group->size(); ++e) {
      subject_material->tet_stiffness_scale[e] = scale[(*tet_group)[e]];
    }
  }
  Json takes = Json::array();
  std::mt19937_64 rng(seed * 7919 + 17);
  std::normal_distribution<double> noise(0.0, 1.0);
  for (const TakeSpec& spec : Specs(seed)) {
    sim::PerformanceOptions perform;
    perform.expression = "neutral";
    perform.motion = spec.motion;
    perform.seconds = seconds;
    perform.seed = seed;
    perform.tissue.fundamental_hz = subject_hz;
    perform.tissue.damping_ratio = subject_damping;
    perform.material = subject_material;
    auto simulated = sim::SimulatePerformance(face, perform);
    if (!simulated.ok()) {
      std::fprintf(stderr, "skull_pose_bench: %s: %s\n", spec.name.c_str(),
                   simulated.status().message().c_str());
      return 1;
    }
    const Take& take = *simulated;
    const int first = static_cast<int>(std::lround(skip_s * take.info.fps));
    const int markers = static_cast<int>(face.markers.size());
    std::vector<reconstruct::MarkerState> states(markers, reconstruct::MarkerState::kObserved);
    std::vector<double> confidence(markers, 1.0);
    std::vector<PoseError> errors(variants.size());
    double normal_sq = 0, offset_sq = 0;
    long offset_n = 0;
    const PointCache& offsets = take.channels.at("dynamic_offset");
    // Every frame's markers, for the take-level reference (EstimateTake uses the fade-in too).
    std::vector<reconstruct::TrackedFrame> tracked(take.frame_count());
    for (int f = 0; f < take.frame_count(); ++f) {
      const Eigen::Matrix3Xd positions = take.FramePositions(f);
      Eigen::Matrix3Xd in_world(3, markers);
      for (int m = 0; m < markers; ++m) {
        in_world.col(m) = face.markers[m].point.Evaluate(positions) +
                          noise_mm * Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
      }
      tracked[f].positions_in_world = in_world;
      tracked[f].states = states;
      tracked[f].confidence = confidence;
      if (f < first) continue;
      const Rigid3& truth = take.world_from_skull[f];
      std::vector<Rigid3> estimates;
      for (size_t v = 0; v < variants.size(); ++v) {
        // The initial pose is only the fallback of a frame with too few markers (never here).
        estimates.push_back(
            estimators[v].Estimate(in_world, states, confidence, Rigid3()).world_from_skull);
      }
      for (size_t v = 0; v < estimates.size(); ++v) errors[v].Add(truth, estimates[v]);
      const Eigen::Matrix3Xf frame_offsets = offsets.Frame(f);
      for (int m : stable) {
        const Eigen::Vector3d offset = face.markers[m].point.Evaluate(frame_offsets);
        const Eigen::Vector3d normal = face.markers[m].point.Evaluate(normals).normalized();
        normal_sq += std::pow(offset.dot(normal), 2);
        offset_sq += offset.squaredNorm();
        ++offset_n;
      }
    }
    // The default estimator over the whole take with the take-level reference
    // (SkullPoseEstimator::EstimateTake, as the pipeline runs it).
    const reconstruct::SkullPoseEstimator take_estimator(face, reconstruct::SkullPoseOptions());
    reconstruct::TakeReferenceResult reference;
    const std::vector<reconstruct::SkullPoseResult> take_results =
        take_estimator.EstimateTake(tracked, &reference);
    PoseError take_error;
    for (int f = first; f < take.frame_count(); ++f)
      take_error.Add(take.world_from_skull[f], take_results[f].world_from_skull);
    const int frames = take.frame_count() - first;
    Json by_variant = Json::object();
    by_variant["default_take_reference"] = take_error.ToJson(frames);
    by_variant["default_take_reference"]["reference_correction_rms_mm"] =
        reference.applied ? reference.correction_rms_mm : 0.0;
    for (size_t v = 0; v < errors.size(); ++v)
      by_variant[variants[v].name] = errors[v].ToJson(frames);
    takes.push_back({{"take", spec.name},
                     {"frames_scored", frames},
                     {"stable_marker_offset_rms_mm", std::sqrt(offset_sq / offset_n)},
                     {"stable_marker_offset_normal_share", offset_sq > 0 ? normal_sq / offset_sq : 0},
                     {"pose_error", by_variant}});
    std::fprintf(stderr, "%s done\n", spec.name.c_str());
  }
  const Json out = {{"bench", "skull_pose"},
                    {"face", "procedural, neutral"},
                    {"stable_markers", stable.size()},
                    {"noise_mm", noise_mm},
                    {"seconds", seconds},
                    {"skip_s", skip_s},
                    {"seed", seed},
                    {"subject_fundamental_hz", subject_hz},
                    {"subject_damping_ratio", subject_damping},
                    {"subject_stable_regions_stiffness",
                     heterogeneous ? "forehead x1.6, nose bridge x0.6, temples x1.3" : "uniform"},
                    {"takes", takes}};
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
