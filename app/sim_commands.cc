// `facedyn sim face` and `facedyn sim perform`: the simulated subject and its performances.

#include <memory>
#include <string>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "app/command.h"
#include "app/performance_flags.h"
#include "core/face_rig.h"
#include "core/take.h"
#include "physics/face_anatomy.h"
#include "sim/ict_import.h"
#include "sim/performance.h"
#include "sim/procedural_face.h"

namespace facedyn::app {
StatusOr<FaceRig> LoadFace(const std::string& spec) {
  if (spec == "procedural") return sim::MakeProceduralFace(sim::ProceduralFaceOptions());
  return LoadFaceRig(spec);
}

void AddSimCommands(CLI::App& app, CommandRunner* selected) {
  auto* sim = app.add_subcommand("sim", "The simulated stage: faces and their physics");
  sim->require_subcommand(1);

  struct FaceOptions {
    std::string out;
    std::string ict_dir;
    std::string identity;
    int vertices = sim::ProceduralFaceOptions().target_vertex_count;
  };
  auto face_options = std::make_shared<FaceOptions>();
  auto* face = sim->add_subcommand("face", "Build a FaceRig: procedural (default) or imported from ICT-FaceKit");
  face->add_option("--out", face_options->out, "FaceRig folder to write")->required();
  face->add_option("--ict", face_options->ict_dir, "ICT-FaceKit folder (as downloaded) to import instead");
  face->add_option("--identity", face_options->identity,
                   "ICT identity weights, e.g. identity000:1.5,identity002:-0.5 (with --ict)");
  face->add_option("--vertices", face_options->vertices, "Procedural face vertex count (4000-10000)")
      ->capture_default_str();
  face->callback([face_options, selected] {
    *selected = [face_options]() -> Status {
      FaceRig rig;
      if (!face_options->ict_dir.empty()) {
        sim::IctImportOptions options;
        options.dir = face_options->ict_dir;
        if (!face_options->identity.empty()) {
          FACEDYN_ASSIGN_OR_RETURN(options.identity_weights, sim::ParseIdentitySpec(face_options->identity));
        }
        FACEDYN_ASSIGN_OR_RETURN(rig, sim::ImportIctFaceKit(options));
      } else {
        if (!face_options->identity.empty()) return InvalidArgumentError("--identity needs --ict");
        sim::ProceduralFaceOptions options;
        options.target_vertex_count = face_options->vertices;
        FACEDYN_ASSIGN_OR_RETURN(rig, sim::MakeProceduralFace(options));
      }
      FACEDYN_RETURN_IF_ERROR(SaveFaceRig(rig, face_options->out));
      spdlog::info("wrote face rig '{}' to {}: {} vertices, {} blendshapes, {} skin samples, {} markers",
                   rig.name, face_options->out, rig.vertex_count(), rig.blendshape_names.size(),
                   rig.skin_samples.size(), rig.markers.size());
      return Status::Ok();
    };
  });

  struct PerformOptions {
    std::string face = "procedural";
    std::string motion = "platform";
    std::string out;
    sim::PerformanceOptions performance;
  };
  auto perform_options = std::make_shared<PerformOptions>();
  auto& p = perform_options->performance;
  auto* perform = sim->add_subcommand(
      "perform", "Simulate a take: dynamic skin plus the exact quasistatic channel");
  perform->add_option("--face", perform_options->face, "FaceRig folder, or 'procedural'")->capture_default_str();
  AddPerformanceFlags(perform, &p, &perform_options->motion);
  perform->add_option("--fundamental-hz", p.tissue.fundamental_hz, "Neutral tissue's lowest natural frequency")
      ->capture_default_str();
  perform->add_option("--damping-ratio", p.tissue.damping_ratio, "Tissue damping ratio at the fundamental")
      ->capture_default_str();
  perform->add_option("--out", perform_options->out, "Take folder to write")->required();
  perform->callback([perform_options, selected] {
    *selected = [perform_options]() -> Status {
      sim::PerformanceOptions options = perform_options->performance;
      FACEDYN_ASSIGN_OR_RETURN(options.motion.kind, sim::ParseMotionKind(perform_options->motion, &options.motion.file));
      options.motion.seed = options.seed;
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(perform_options->face));
      sim::PerformanceSummary summary;
      FACEDYN_ASSIGN_OR_RETURN(const Take take, sim::SimulatePerformance(rig, options, &summary));
      FACEDYN_RETURN_IF_ERROR(SaveTake(take, perform_options->out));
      spdlog::info("wrote {} ({} frames; E = {:.2f} kPa, {} substeps/frame, simulated in {:.1f} s)",
                   perform_options->out, take.frame_count(), summary.youngs_modulus_kpa,
                   summary.substeps_per_frame, summary.simulate_s);
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
