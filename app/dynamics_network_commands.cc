// `facedyn dynamics train-removal | train | remove | train-synthesis | synthesize | retarget |
// train-modal`: the networks of Zoss et al. 2020 on Take folders (dynamics/removal_model.h,
// synthesis_model.h) and the modal model (dynamics/modal_synthesis.h), which `remove`,
// `synthesize` and `retarget` take under the same --model (told apart by the file's magic).

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "app/command.h"
#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/take.h"
#include "dynamics/joint_training.h"
#include "dynamics/modal_synthesis.h"
#include "dynamics/propagation.h"
#include "dynamics/quasistatic.h"
#include "dynamics/removal_model.h"
#include "dynamics/synthesis_model.h"
#include "sim/expressions.h"

namespace facedyn::app {
namespace {

StatusOr<std::vector<Take>> LoadTakes(const std::vector<std::string>& dirs) {
  std::vector<Take> takes;
  for (const std::string& dir : dirs) {
    StatusOr<Take> take = LoadTake(dir);
    if (!take.ok()) return take.status();
    spdlog::info("loaded {} ({} frames at {} fps)", dir, take->frame_count(), take->info.fps);
    takes.push_back(std::move(take).value());
  }
  return takes;
}

std::vector<dynamics::TrainingTake> AsTraining(const std::vector<Take>& takes, const FaceRig& rig) {
  std::vector<dynamics::TrainingTake> training;
  for (const Take& take : takes) training.push_back({&take, &rig});
  return training;
}

Json SummaryJson(const learn::MlpTrainSummary& summary) {
  return {{"training_rows", summary.training_rows},
          {"validation_rows", summary.validation_rows},
          {"epochs", summary.train_loss.size()},
          {"final_train_loss", summary.train_loss.empty() ? 0.0 : summary.train_loss.back()},
          {"final_validation_loss",
           summary.validation_loss.empty() ? 0.0 : summary.validation_loss.back()},
          {"train_s", summary.train_s},
          {"rows_per_s", summary.rows_per_s}};
}

// Head motion for synthesis: a take folder (its skull.csv) or a skull.csv file.
StatusOr<std::vector<Rigid3>> LoadMotion(const std::string& spec) {
  if (std::filesystem::is_directory(spec)) {
    FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(spec));
    return take.world_from_skull;
  }
  std::vector<double> time_s;
  std::vector<Rigid3> poses;
  FACEDYN_RETURN_IF_ERROR(ReadTransformCsv(spec, &time_s, &poses));
  return poses;
}

// Trims a take to its first `frames` frames (positions, poses, times, channels).
void TrimTake(int frames, Take* take) {
  take->positions.positions.conservativeResize(Eigen::NoChange, frames);
  for (auto& [name, cache] : take->channels)
    cache.positions.conservativeResize(Eigen::NoChange, frames);
  take->world_from_skull.resize(frames);
  if (!take->skull_from_jaw.empty()) take->skull_from_jaw.resize(frames);
  take->time_s.resize(frames);
}

// A synthesis model file: the modal model's (by its magic) or H's.
Status LoadSynthesisModel(const std::string& path,
                          std::optional<dynamics::ModalSynthesisModel>* modal,
                          std::optional<dynamics::SynthesisModel>* network) {
  if (dynamics::IsModalModelFile(path)) {
    FACEDYN_ASSIGN_OR_RETURN(*modal, dynamics::ModalSynthesisModel::Load(path));
  } else {
    FACEDYN_ASSIGN_OR_RETURN(*network, dynamics::SynthesisModel::Load(path));
  }
  return Status::Ok();
}

}  // namespace

void AddDynamicsNetworkCommands(CLI::App* dynamics, CommandRunner* selected) {
  // --- train-removal ---
  struct TrainRemovalCommand {
    std::vector<std::string> takes;
    std::vector<std::string> twin_takes;
    double twin_weight = 1.0;
    std::string face = "procedural";
    std::string out;
    std::string targets = "moving-average";
    dynamics::RemovalTrainOptions options;
    bool json = false;
  };
  auto train_removal = std::make_shared<TrainRemovalCommand>();
  auto* train_removal_cmd = dynamics->add_subcommand(
      "train-removal",
      "Train the removal network F (Zoss et al. 2020, sec. 5) on held-expression takes");
  train_removal_cmd->add_option("--takes", train_removal->takes, "Training take folders")
      ->required()
      ->expected(1, -1);
  train_removal_cmd
      ->add_option("--twin-takes", train_removal->twin_takes,
                   "Takes of the subject's fitted twin (`facedyn twin perform`), trained beside "
                   "--takes on the twin's own exact quasistatic: head motions the session could "
                   "not capture")
      ->expected(1, -1);
  train_removal_cmd
      ->add_option("--twin-weight", train_removal->twin_weight,
                   "How much each twin take's frames count against a captured take's (each "
                   "frame drawn this many times per epoch; fractions draw a seeded subset)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  train_removal_cmd->add_option("--face", train_removal->face, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  train_removal_cmd->add_option("--out", train_removal->out, "Model file to write (e.g. F.pt)")
      ->required();
  train_removal_cmd
      ->add_option("--targets", train_removal->targets,
                   "moving-average (Eq. 5-6, the paper), platform-synchronous (fit at each "
                   "take's recorded platform frequency), platform-synchronous-where-known "
                   "(platform takes fitted, other head motion moving-average), held-mean (each "
                   "take's mean shape in the skull frame over its held frames), "
                   "platform-synchronous-else-held-mean (platform takes fitted, other head motion "
                   "held-mean) or exact (simulated takes' quasistatic)")
      ->check(CLI::IsMember(dynamics::RemovalTargetsNames(/*include_exact=*/true)))
      ->capture_default_str();
  train_removal_cmd
      ->add_option("--target-trend-degree", train_removal->options.target_trend_degree,
                   "Platform-synchronous targets: degree of the polynomial fitted with the "
                   "sinusoids (0: a constant; 2 for takes whose expression changes)")
      ->capture_default_str();
  train_removal_cmd
      ->add_option("--target-min-periods", train_removal->options.target_min_periods,
                   "Platform-synchronous targets: shortest window in platform periods")
      ->capture_default_str();
  train_removal_cmd->add_option("--epochs", train_removal->options.train.epochs)
      ->capture_default_str();
  train_removal_cmd->add_option("--batch", train_removal->options.train.batch_size)
      ->capture_default_str();
  train_removal_cmd->add_option("--learning-rate", train_removal->options.train.learning_rate)
      ->capture_default_str();
  train_removal_cmd
      ->add_option("--validation", train_removal->options.validation_fraction,
                   "Fraction of frames held out for validation")
      ->capture_default_str();
  train_removal_cmd->add_option("--seed", train_removal->options.train.seed)->capture_default_str();
  train_removal_cmd
      ->add_option("--threads", train_removal->options.train.num_threads,
                   "LibTorch threads (0: default); the same count gives the same model")
      ->capture_default_str();
  train_removal_cmd
      ->add_option("--lr-final", train_removal->options.train.final_learning_rate_fraction,
                   "Decay the learning rate exponentially to this fraction at the last epoch")
      ->capture_default_str();
  train_removal_cmd->add_flag_callback(
      "--no-linear-skip", [train_removal] { train_removal->options.linear_skip = false; },
      "The paper's network alone, without the linear map of the inputs added to its output");
  train_removal_cmd->add_flag("--json", train_removal->json, "Print the training summary as JSON");
  train_removal_cmd->callback([train_removal, selected] {
    *selected = [train_removal]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(train_removal->options.targets,
                               dynamics::ParseRemovalTargets(train_removal->targets));
      if (Status status = train_removal->options.Check(); !status.ok()) {
        return InvalidArgumentError("train-removal: " + status.message());
      }
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(train_removal->face));
      FACEDYN_ASSIGN_OR_RETURN(const std::vector<Take> takes, LoadTakes(train_removal->takes));
      FACEDYN_ASSIGN_OR_RETURN(const std::vector<Take> twin_takes,
                               LoadTakes(train_removal->twin_takes));
      std::vector<dynamics::TrainingTake> training = AsTraining(takes, rig);
      for (size_t k = 0; k < twin_takes.size(); ++k) {
        // Only the twin's own simulation may bring exact targets: a simulator take here would
        // hand the method the world's truth.
        if (twin_takes[k].info.source != "twin perform") {
          return InvalidArgumentError(fmt::format(
              "train-removal: --twin-takes {} is not a twin take (its source is \"{}\", not "
              "\"twin perform\")",
              train_removal->twin_takes[k], twin_takes[k].info.source));
        }
        training.push_back({&twin_takes[k], &rig, dynamics::RemovalTargets::kExact,
                            train_removal->twin_weight});
      }
      learn::MlpTrainSummary summary;
      FACEDYN_ASSIGN_OR_RETURN(
          const dynamics::RemovalModel model,
          dynamics::TrainRemoval(training, train_removal->options, &summary));
      FACEDYN_RETURN_IF_ERROR(model.Save(train_removal->out));
      spdlog::info("wrote {} ({} training rows, validation loss {:.4g})", train_removal->out,
                   summary.training_rows,
                   summary.validation_loss.empty() ? 0.0 : summary.validation_loss.back());
      if (train_removal->json)
        std::printf("%s\n",
                    SummaryJson(summary).dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      return Status::Ok();
    };
  });

  // --- remove ---
  struct RemoveCommand {
    std::string take, model, face = "procedural", out;
    bool lowpass_after = false;
    bool json = false;
  };
  auto remove = std::make_shared<RemoveCommand>();
  auto* remove_cmd = dynamics->add_subcommand(
      "remove",
      "Remove secondary dynamics from a take with a trained F (Eq. 7) or a modal model (the "
      "offsets it predicts from the take's head motion), propagated to every vertex; writes the "
      "quasistatic take with channel dynamic_offset");
  remove_cmd->add_option("--take", remove->take, "Dynamic take folder")->required();
  remove_cmd
      ->add_option("--model", remove->model,
                   "Removal model (train-removal --out) or modal model (train-modal --out)")
      ->required();
  remove_cmd->add_flag("--lowpass-after", remove->lowpass_after,
                       "Modal model only: follow the removal with the skull-frame low-pass whose "
                       "cutoff the model's validation error calls for (recorded in the take's "
                       "metadata as removal_lowpass_hz)");
  remove_cmd->add_option("--face", remove->face, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  remove_cmd->add_option("--out", remove->out, "Output take folder")->required();
  remove_cmd->add_flag("--json", remove->json, "Print timings as JSON");
  remove_cmd->callback([remove, selected] {
    *selected = [remove]() -> Status {
      if (dynamics::IsModalModelFile(remove->model)) {
        FACEDYN_ASSIGN_OR_RETURN(const dynamics::ModalSynthesisModel modal,
                                 dynamics::ModalSynthesisModel::Load(remove->model));
        FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(remove->face));
        FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(remove->take));
        double cutoff_hz = 0.0;
        StatusOr<Take> removed = remove->lowpass_after
                                     ? modal.RemoveThenLowPass(take, rig, &cutoff_hz)
                                     : modal.Remove(take, rig);
        if (!removed.ok()) return removed.status().WithContext(remove->take);
        FACEDYN_RETURN_IF_ERROR(SaveTake(*removed, remove->out));
        spdlog::info("wrote {} ({} frames, modal removal{})", remove->out, removed->frame_count(),
                     remove->lowpass_after ? fmt::format(", low-pass at {:.2f} Hz", cutoff_hz)
                                           : std::string());
        if (remove->json) {
          Json json = {{"frames", removed->frame_count()}, {"model", "modal"}};
          if (remove->lowpass_after) json["lowpass_hz"] = cutoff_hz;
          std::printf("%s\n", json.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
        }
        return Status::Ok();
      }
      if (remove->lowpass_after) {
        return InvalidArgumentError(
            "remove: --lowpass-after needs a modal model (train-modal --out); " + remove->model +
            " is not one");
      }
      FACEDYN_ASSIGN_OR_RETURN(const dynamics::RemovalModel model,
                               dynamics::RemovalModel::Load(remove->model));
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(remove->face));
      FACEDYN_ASSIGN_OR_RETURN(const Take take, LoadTake(remove->take));
      dynamics::RemovalSummary summary;
      StatusOr<Take> removed = dynamics::RemoveDynamics(model, take, rig, nullptr, &summary);
      if (!removed.ok()) return removed.status().WithContext(remove->take);
      FACEDYN_RETURN_IF_ERROR(SaveTake(*removed, remove->out));
      spdlog::info("wrote {} ({} frames, {:.0f} frames/s)", remove->out, removed->frame_count(),
                   summary.frames_per_s);
      if (remove->json) {
        std::printf("%s\n", Json({{"frames", removed->frame_count()},
                                  {"predict_s", summary.predict_s},
                                  {"propagate_s", summary.propagate_s},
                                  {"frames_per_s", summary.frames_per_s}})
                                .dump(2, ' ', false, kJsonReplaceInvalidUtf8)
                                .c_str());
      }
      return Status::Ok();
    };
  });

  // --- train: F and H together (dynamics/joint_training.h) ---
  struct TrainJointCommand {
    std::vector<std::string> takes;
    std::vector<std::string> performances;
    std::vector<std::string> twin_takes;
    double twin_weight = 1.0;
    std::string face = "procedural";
    std::string out_removal, out_synthesis;
    std::string targets = "platform-synchronous-where-known";
    dynamics::JointTrainOptions options;
    bool json = false;
  };
  auto train_joint = std::make_shared<TrainJointCommand>();
  auto* train_joint_cmd = dynamics->add_subcommand(
      "train",
      "Train F and H together (Zoss et al. 2020, sec. 8.1): F on held-expression takes, H on "
      "F's decomposition of them, then both fine-tuned with the cycle loss on performances "
      "(takes with no target: talking, walking), beside each network's own loss");
  train_joint_cmd
      ->add_option("--takes", train_joint->takes,
                   "Held-expression take folders (F's targets are estimated from them)")
      ->required()
      ->expected(1, -1);
  train_joint_cmd
      ->add_option("--performances", train_joint->performances,
                   "Performance take folders: only their positions and head motion are read")
      ->required()
      ->expected(1, -1);
  train_joint_cmd
      ->add_option("--twin-takes", train_joint->twin_takes,
                   "Takes of the subject's fitted twin (`facedyn twin perform`), held takes on "
                   "the twin's own exact quasistatic, as train-removal's")
      ->expected(1, -1);
  train_joint_cmd
      ->add_option("--twin-weight", train_joint->twin_weight,
                   "How much each twin take's frames count against a captured take's")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  train_joint_cmd->add_option("--face", train_joint->face, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  train_joint_cmd->add_option("--out-removal", train_joint->out_removal, "F's file (e.g. F.pt)")
      ->required();
  train_joint_cmd->add_option("--out-synthesis", train_joint->out_synthesis, "H's file (e.g. H.pt)")
      ->required();
  train_joint_cmd
      ->add_option("--targets", train_joint->targets,
                   "F's targets on the held takes: moving-average, platform-synchronous, "
                   "platform-synchronous-where-known, held-mean or "
                   "platform-synchronous-else-held-mean (never the simulator's exact ones here)")
      ->check(CLI::IsMember(dynamics::RemovalTargetsNames(/*include_exact=*/false)))
      ->capture_default_str();
  train_joint_cmd->add_option("--epochs", train_joint->options.removal.train.epochs, "F's epochs")
      ->capture_default_str();
  train_joint_cmd
      ->add_option("--synthesis-epochs", train_joint->options.synthesis.train.epochs, "H's epochs")
      ->capture_default_str();
  train_joint_cmd
      ->add_option("--joint-steps", train_joint->options.joint.steps,
                   "Adam steps of the joint phase (each: a batch of F's rows, of H's, and of "
                   "performance frames)")
      ->capture_default_str();
  train_joint_cmd
      ->add_option("--cycle-weight", train_joint->options.joint.pair_weight,
                   "Weight of the cycle loss against the supervised ones")
      ->capture_default_str();
  train_joint_cmd
      ->add_option("--joint-lr", train_joint->options.joint.learning_rate,
                   "Learning rate of the joint phase")
      ->capture_default_str();
  train_joint_cmd->add_flag_callback(
      "--cycle-trains-f-only",
      [train_joint] { train_joint->options.joint.pair_trains_second = false; },
      "Keep the cycle's gradient from H (H then trains on its own loss only)");
  train_joint_cmd->add_flag(
      "--early-stopping", train_joint->options.joint.keep_least_validation,
      "Keep the joint phase's parameters from its report of least validation objective (F's "
      "and H's held-out losses on held-take rows plus the cycle's on held-out performance "
      "frames) instead of the last");
  train_joint_cmd->add_option("--seed", train_joint->options.removal.train.seed)
      ->capture_default_str();
  train_joint_cmd
      ->add_option("--threads", train_joint->options.removal.train.num_threads,
                   "LibTorch threads (0: default); the same count gives the same models")
      ->capture_default_str();
  train_joint_cmd->add_flag("--json", train_joint->json, "Print the training summary as JSON");
  train_joint_cmd->callback([train_joint, selected] {
    *selected = [train_joint]() -> Status {
      dynamics::JointTrainOptions& options = train_joint->options;
      FACEDYN_ASSIGN_OR_RETURN(options.removal.targets,
                               dynamics::ParseRemovalTargets(train_joint->targets));
      // One seed and thread count for the three phases.
      options.synthesis.train.seed = options.removal.train.seed;
      options.joint.seed = options.removal.train.seed;
      options.synthesis.train.num_threads = options.removal.train.num_threads;
      options.joint.num_threads = options.removal.train.num_threads;
      if (Status status = options.Check(); !status.ok()) {
        return InvalidArgumentError("train: " + status.message());
      }
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(train_joint->face));
      FACEDYN_ASSIGN_OR_RETURN(const std::vector<Take> takes, LoadTakes(train_joint->takes));
      FACEDYN_ASSIGN_OR_RETURN(const std::vector<Take> performances,
                               LoadTakes(train_joint->performances));
      FACEDYN_ASSIGN_OR_RETURN(const std::vector<Take> twin_takes,
                               LoadTakes(train_joint->twin_takes));
      std::vector<dynamics::TrainingTake> held = AsTraining(takes, rig);
      for (size_t k = 0; k < twin_takes.size(); ++k) {
        if (twin_takes[k].info.source != "twin perform") {
          return InvalidArgumentError(fmt::format(
              "train: --twin-takes {} is not a twin take (its source is \"{}\", not \"twin "
              "perform\")",
              train_joint->twin_takes[k], twin_takes[k].info.source));
        }
        held.push_back(
            {&twin_takes[k], &rig, dynamics::RemovalTargets::kExact, train_joint->twin_weight});
      }
      dynamics::JointTrainSummary summary;
      FACEDYN_ASSIGN_OR_RETURN(
          const dynamics::JointModels models,
          dynamics::TrainJoint(held, AsTraining(performances, rig), options, &summary));
      FACEDYN_RETURN_IF_ERROR(models.removal.Save(train_joint->out_removal));
      FACEDYN_RETURN_IF_ERROR(models.synthesis.Save(train_joint->out_synthesis));
      const learn::MlpPairTrainSummary& joint = summary.joint;
      spdlog::info("wrote {} and {} (cycle loss {:.4g} mm^2 on {} performance frames)",
                   train_joint->out_removal, train_joint->out_synthesis,
                   joint.pair_loss.empty() ? 0.0 : joint.pair_loss.back(),
                   summary.performance_frames);
      if (train_joint->json) {
        const Json out = {
            {"removal", SummaryJson(summary.removal)},
            {"synthesis", SummaryJson(summary.synthesis)},
            {"joint",
             {{"steps", joint.steps},
              {"kept_report", joint.kept_report},
              {"performance_frames", summary.performance_frames},
              {"performance_validation_frames", summary.performance_validation_frames},
              {"removal_loss_mm2", joint.first_loss},
              {"synthesis_loss_mm2", joint.second_loss},
              {"cycle_loss_mm2", joint.pair_loss},
              {"removal_validation_loss_mm2", joint.first_validation_loss},
              {"synthesis_validation_loss_mm2", joint.second_validation_loss},
              {"cycle_validation_loss_mm2", joint.pair_validation_loss},
              {"train_s", joint.train_s}}}};
        std::printf("%s\n", out.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      }
      return Status::Ok();
    };
  });

  // --- train-synthesis ---
  struct TrainSynthesisCommand {
    std::vector<std::string> takes;
    std::string face = "procedural", out, removal_model;
    bool exact = false;
    dynamics::SynthesisTrainOptions options;
    bool json = false;
  };
  auto train_synthesis = std::make_shared<TrainSynthesisCommand>();
  auto* train_synthesis_cmd = dynamics->add_subcommand(
      "train-synthesis",
      "Train the synthesis network H (Zoss et al. 2020, sec. 6) on decomposed takes: the output "
      "of `dynamics remove`, dynamic takes with --removal-model F.pt, or simulated takes with "
      "--exact");
  train_synthesis_cmd->add_option("--takes", train_synthesis->takes, "Training take folders")
      ->required()
      ->expected(1, -1);
  train_synthesis_cmd
      ->add_option("--face", train_synthesis->face, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  train_synthesis_cmd->add_option("--out", train_synthesis->out, "Model file to write (e.g. H.pt)")
      ->required();
  auto* removal_option = train_synthesis_cmd->add_option(
      "--removal-model", train_synthesis->removal_model,
      "Decompose dynamic takes with this removal model first (the paper's way)");
  train_synthesis_cmd
      ->add_flag(
          "--exact", train_synthesis->exact,
          "Decompose simulated takes exactly (their quasistatic and dynamic_offset channels)")
      ->excludes(removal_option);
  train_synthesis_cmd->add_option("--epochs", train_synthesis->options.train.epochs)
      ->capture_default_str();
  train_synthesis_cmd->add_option("--batch", train_synthesis->options.train.batch_size)
      ->capture_default_str();
  train_synthesis_cmd->add_option("--learning-rate", train_synthesis->options.train.learning_rate)
      ->capture_default_str();
  train_synthesis_cmd->add_option("--validation", train_synthesis->options.validation_fraction)
      ->capture_default_str();
  train_synthesis_cmd->add_option("--seed", train_synthesis->options.train.seed)
      ->capture_default_str();
  train_synthesis_cmd->add_option("--threads", train_synthesis->options.train.num_threads)
      ->capture_default_str();
  train_synthesis_cmd->add_flag("--json", train_synthesis->json,
                                "Print the training summary as JSON");
  train_synthesis_cmd->callback([train_synthesis, selected] {
    *selected = [train_synthesis]() -> Status {
      if (Status status = train_synthesis->options.Check(); !status.ok()) {
        return InvalidArgumentError("train-synthesis: " + status.message());
      }
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(train_synthesis->face));
      FACEDYN_ASSIGN_OR_RETURN(std::vector<Take> takes, LoadTakes(train_synthesis->takes));
      if (train_synthesis->exact) {
        for (size_t k = 0; k < takes.size(); ++k) {
          StatusOr<Take> decomposed = dynamics::DecomposeExact(takes[k]);
          if (!decomposed.ok()) return decomposed.status().WithContext(train_synthesis->takes[k]);
          takes[k] = std::move(decomposed).value();
        }
      } else if (!train_synthesis->removal_model.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(const dynamics::RemovalModel removal,
                                 dynamics::RemovalModel::Load(train_synthesis->removal_model));
        FACEDYN_ASSIGN_OR_RETURN(const dynamics::SamplePropagation propagation,
                                 dynamics::SamplePropagation::Build(rig));
        for (size_t k = 0; k < takes.size(); ++k) {
          StatusOr<Take> removed = dynamics::RemoveDynamics(removal, takes[k], rig, &propagation);
          if (!removed.ok()) return removed.status().WithContext(train_synthesis->takes[k]);
          takes[k] = std::move(removed).value();
        }
      }
      learn::MlpTrainSummary summary;
      FACEDYN_ASSIGN_OR_RETURN(
          const dynamics::SynthesisModel model,
          dynamics::TrainSynthesis(AsTraining(takes, rig), train_synthesis->options, &summary));
      FACEDYN_RETURN_IF_ERROR(model.Save(train_synthesis->out));
      spdlog::info("wrote {} ({} training frames)", train_synthesis->out, summary.training_rows);
      if (train_synthesis->json)
        std::printf("%s\n",
                    SummaryJson(summary).dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      return Status::Ok();
    };
  });

  // --- synthesize and retarget share the composition ---
  struct SynthesizeCommand {
    std::string take, motion, model, face = "procedural", out;
    std::string expression;  // retarget: held expression of the target face
    std::string naive_out;   // retarget: also write the naive per-vertex transfer
    std::string source_face = "procedural";
  };
  auto synthesize = std::make_shared<SynthesizeCommand>();
  auto* synthesize_cmd = dynamics->add_subcommand(
      "synthesize",
      "Compose new secondary dynamics for a quasistatic take under a new head motion with a "
      "trained H (Zoss et al. 2020, sec. 6)");
  synthesize_cmd->add_option("--take", synthesize->take, "Quasistatic take folder")->required();
  synthesize_cmd
      ->add_option("--motion", synthesize->motion,
                   "New head motion: a take folder or a skull.csv file")
      ->required();
  synthesize_cmd
      ->add_option("--model", synthesize->model,
                   "Synthesis model (train-synthesis --out) or modal model (train-modal --out)")
      ->required();
  synthesize_cmd->add_option("--face", synthesize->face, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  synthesize_cmd->add_option("--out", synthesize->out, "Output take folder")->required();
  synthesize_cmd->callback([synthesize, selected] {
    *selected = [synthesize]() -> Status {
      std::optional<dynamics::ModalSynthesisModel> modal;
      std::optional<dynamics::SynthesisModel> network;
      FACEDYN_RETURN_IF_ERROR(LoadSynthesisModel(synthesize->model, &modal, &network));
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(synthesize->face));
      FACEDYN_ASSIGN_OR_RETURN(Take quasistatic, LoadTake(synthesize->take));
      FACEDYN_ASSIGN_OR_RETURN(std::vector<Rigid3> motion, LoadMotion(synthesize->motion));
      const int frames = std::min<int>(quasistatic.frame_count(), static_cast<int>(motion.size()));
      if (frames < 1) return InvalidArgumentError("synthesize: the motion has no poses");
      if (frames != quasistatic.frame_count() || frames != static_cast<int>(motion.size())) {
        spdlog::warn(
            "synthesize: the take has {} frames and the motion {} poses; using the first {}",
            quasistatic.frame_count(), motion.size(), frames);
        TrimTake(frames, &quasistatic);
        motion.resize(frames);
      }
      StatusOr<Take> result = modal
                                  ? modal->Synthesize(quasistatic, motion, synthesize->motion, rig)
                                  : dynamics::SynthesizeDynamics(*network, quasistatic, motion,
                                                                 synthesize->motion, rig);
      if (!result.ok()) return result.status().WithContext(synthesize->take);
      FACEDYN_RETURN_IF_ERROR(SaveTake(*result, synthesize->out));
      spdlog::info("wrote {} ({} frames)", synthesize->out, result->frame_count());
      return Status::Ok();
    };
  });

  auto retarget = std::make_shared<SynthesizeCommand>();
  auto* retarget_cmd = dynamics->add_subcommand(
      "retarget",
      "Root-motion retargeting (Zoss et al. 2020, Figs. 9-10): the source take's head motion on "
      "the target subject, with dynamics from the target's H; optionally the naive per-vertex "
      "transfer for comparison");
  retarget_cmd
      ->add_option("--source", retarget->motion,
                   "Source take (its head motion; with --naive-out also its dynamic_offset)")
      ->required();
  retarget_cmd->add_option("--face", retarget->face, "Target FaceRig folder, or 'procedural'")
      ->capture_default_str();
  retarget_cmd
      ->add_option("--model", retarget->model,
                   "The target subject's synthesis model or modal model (train-modal --out)")
      ->required();
  auto* take_option = retarget_cmd->add_option(
      "--take", retarget->take, "Target quasistatic take (default: the target holds --expression)");
  retarget_cmd
      ->add_option("--expression", retarget->expression,
                   "Held expression of the target face (default neutral)")
      ->excludes(take_option);
  retarget_cmd->add_option("--out", retarget->out, "Output take folder")->required();
  retarget_cmd->add_option("--naive-out", retarget->naive_out,
                           "Also write the naive per-vertex delta transfer here (Fig. 10b)");
  retarget_cmd
      ->add_option("--source-face", retarget->source_face,
                   "Source FaceRig (samples for --naive-out), or 'procedural'")
      ->capture_default_str();
  retarget_cmd->callback([retarget, selected] {
    *selected = [retarget]() -> Status {
      std::optional<dynamics::ModalSynthesisModel> modal;
      std::optional<dynamics::SynthesisModel> network;
      FACEDYN_RETURN_IF_ERROR(LoadSynthesisModel(retarget->model, &modal, &network));
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(retarget->face));
      FACEDYN_ASSIGN_OR_RETURN(const Take source, LoadTake(retarget->motion));
      Take target;
      if (!retarget->take.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(target, LoadTake(retarget->take));
        if (target.frame_count() < source.frame_count()) {
          return InvalidArgumentError(
              "retarget: the target take has " + std::to_string(target.frame_count()) +
              " frames, fewer than the source's " + std::to_string(source.frame_count()));
        }
        TrimTake(source.frame_count(), &target);
      } else {
        const std::string expression =
            retarget->expression.empty() ? "neutral" : retarget->expression;
        FACEDYN_ASSIGN_OR_RETURN(const Eigen::VectorXd weights,
                                 sim::ExpressionWeights(rig, expression));
        target = dynamics::HeldShapeTake(rig, rig.Evaluate(weights), source.world_from_skull,
                                         source.info.fps);
        target.info.expression = expression;
      }
      const std::string motion_name = "retargeted from " + retarget->motion;
      StatusOr<Take> result =
          modal ? modal->Synthesize(target, source.world_from_skull, motion_name, rig)
                : dynamics::SynthesizeDynamics(*network, target, source.world_from_skull,
                                               motion_name, rig);
      if (!result.ok()) return result.status().WithContext(retarget->motion);
      FACEDYN_RETURN_IF_ERROR(SaveTake(*result, retarget->out));
      spdlog::info("wrote {} ({} frames)", retarget->out, result->frame_count());
      if (!retarget->naive_out.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(const FaceRig source_rig, LoadFace(retarget->source_face));
        FACEDYN_ASSIGN_OR_RETURN(const Take naive,
                                 dynamics::NaiveDeltaTransfer(source, source_rig, target, rig));
        FACEDYN_RETURN_IF_ERROR(SaveTake(naive, retarget->naive_out));
        spdlog::info("wrote the naive transfer to {}", retarget->naive_out);
      }
      return Status::Ok();
    };
  });

  // --- train-modal ---
  struct TrainModalCommand {
    std::vector<std::string> takes;
    std::string face = "procedural", out;
    std::string decomposition = "held-mean";
    std::string ridge_rule = "minimum";
    dynamics::ModalSynthesisOptions options;
    bool json = false;
  };
  auto train_modal = std::make_shared<TrainModalCommand>();
  auto* train_modal_cmd = dynamics->add_subcommand(
      "train-modal",
      "Train the modal model (dynamics/modal_synthesis.h): a subject's dynamics as a fixed bank "
      "of damped resonators driven by the skull's acceleration and one ridge-fitted linear map, "
      "from held takes decomposed by their held mean; for remove, synthesize and retarget");
  train_modal_cmd->add_option("--takes", train_modal->takes, "Training take folders")
      ->required()
      ->expected(1, -1);
  train_modal_cmd->add_option("--face", train_modal->face, "FaceRig folder, or 'procedural'")
      ->capture_default_str();
  train_modal_cmd->add_option("--out", train_modal->out, "Model file to write (e.g. modal.bin)")
      ->required();
  train_modal_cmd
      ->add_option("--decomposition", train_modal->decomposition,
                   "held-mean: captured held takes, each decomposed by its held part's mean shape "
                   "in the skull frame (no truth); decomposed: takes that already carry a "
                   "dynamic_offset channel (the output of `dynamics remove` or `dynamics "
                   "quasistatic`)")
      ->check(CLI::IsMember({"held-mean", "decomposed"}))
      ->capture_default_str();
  train_modal_cmd
      ->add_option("--resonator-damping", train_modal->options.resonator_damping,
                   "Damping ratio of the resonator bank")
      ->capture_default_str();
  train_modal_cmd
      ->add_option("--seed", train_modal->options.seed,
                   "Seed of the validation blocks (used with a single take)")
      ->capture_default_str();
  train_modal_cmd
      ->add_option("--ridge-rule", train_modal->ridge_rule,
                   "How the ridge is chosen from the validation errors: minimum, or "
                   "one-standard-error (the largest ridge within one standard error of the least; "
                   "several takes needed, else the minimum)")
      ->check(CLI::IsMember(dynamics::RidgeRuleNames()))
      ->capture_default_str();
  train_modal_cmd->add_flag("--json", train_modal->json, "Print the fit's summary as JSON");
  train_modal_cmd->callback([train_modal, selected] {
    *selected = [train_modal]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(train_modal->options.ridge_rule,
                               dynamics::ParseRidgeRule(train_modal->ridge_rule));
      if (Status status = train_modal->options.Check(); !status.ok()) {
        return InvalidArgumentError("train-modal: " + status.message());
      }
      FACEDYN_ASSIGN_OR_RETURN(const FaceRig rig, LoadFace(train_modal->face));
      FACEDYN_ASSIGN_OR_RETURN(std::vector<Take> takes, LoadTakes(train_modal->takes));
      if (train_modal->decomposition == "held-mean") {
        dynamics::QuasistaticOptions held;
        held.method = dynamics::QuasistaticMethod::kHeldMean;
        for (size_t k = 0; k < takes.size(); ++k) {
          StatusOr<Take> decomposed = dynamics::ExtractQuasistatic(takes[k], held);
          if (!decomposed.ok()) return decomposed.status().WithContext(train_modal->takes[k]);
          takes[k] = std::move(decomposed).value();
        }
      }
      dynamics::ModalSynthesisFit fit;
      StatusOr<dynamics::ModalSynthesisModel> model =
          dynamics::ModalSynthesisModel::Train(AsTraining(takes, rig), train_modal->options, &fit);
      if (!model.ok()) return model.status().WithContext("train-modal");
      FACEDYN_RETURN_IF_ERROR(model->Save(train_modal->out));
      spdlog::info(
          "wrote {} ({} training frames; ridge {:g} chosen by {}, expected residual {:.3f} of a "
          "new motion's offsets)",
          train_modal->out, fit.training_frames, fit.chosen_ridge, fit.validation,
          model->validation_residual());
      if (train_modal->json) {
        const Json json = {{"training_frames", fit.training_frames},
                           {"validation", fit.validation},
                           {"validation_frames", fit.validation_frames},
                           {"ridge_tried", train_modal->options.ridge},
                           {"validation_relative", fit.validation_relative},
                           {"validation_standard_error", fit.validation_standard_error},
                           {"ridge_rule", dynamics::RidgeRuleName(fit.ridge_rule)},
                           {"chosen_ridge", fit.chosen_ridge},
                           {"validation_residual", model->validation_residual()}};
        std::printf("%s\n", json.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      }
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
