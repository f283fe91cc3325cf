#include "rig/sweep.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>

#include "core/file_util.h"
#include "rig/session_log.h"
#include "rig/sweep_resume.h"

namespace facedyn::rig {
namespace {

constexpr const char* kLogName = "rig_log.jsonl";
constexpr const char* kSummaryName = "sweep_summary.json";
// A sweep of 100,000 step instances at the shortest hold is already days of vibration; the cap
// exists so that a script cannot make facedyn expand (allocate) an absurd plan. It is applied
// to counts computed in int64 before the grid is expanded: a 10^4 x 10^4 grid was once built
// (10^8 steps, gigabytes) before being counted, and 3000 x 1000 cells x 1000 repeats summed in
// int came out negative and passed.
constexpr int64_t kMaxInstances = 100000;
constexpr int kMaxRepeats = 1000;

uint64_t Fnv1a64(const std::string& bytes) {
  uint64_t hash = 1469598103934665603ull;
  for (const unsigned char c : bytes) {
    hash ^= c;
    hash *= 1099511628211ull;
  }
  return hash;
}

std::string DirectoryOf(const std::string& path) {
  const size_t slash = path.rfind('/');
  return slash == std::string::npos ? "." : path.substr(0, slash);
}

bool FileExists(const std::string& path) {
  struct stat info {};
  return ::stat(path.c_str(), &info) == 0;
}

// Reads the step fields present in `node` over `step` (which carries the defaults).
Status ReadStepFields(const ConfigNode& node, bool hz_required, SweepStep* step) {
  if (hz_required || node.Has("hz")) {
    FACEDYN_ASSIGN_OR_RETURN(step->hz, node.Get<double>("hz"));
  }
  if (node.Has("settle_timeout_s")) {
    FACEDYN_ASSIGN_OR_RETURN(step->settle_timeout_s,
                             node.GetInRange("settle_timeout_s", 0.1, 3600.0));
  }
  if (node.Has("settle_s")) {
    FACEDYN_ASSIGN_OR_RETURN(step->settle_s, node.GetInRange("settle_s", 0.0, 3600.0));
  }
  if (node.Has("hold_s")) {
    FACEDYN_ASSIGN_OR_RETURN(step->hold_s, node.Get<double>("hold_s"));
    if (!(step->hold_s > 0.0 && step->hold_s <= 3600.0)) {
      return node.Error("hold_s", fmt::format("{} s is outside (0, 3600] s", step->hold_s));
    }
  }
  if (node.Has("prompt")) {
    FACEDYN_ASSIGN_OR_RETURN(step->prompt, node.Get<std::string>("prompt"));
  }
  if (node.Has("repeats")) {
    // Read wide so that 3000000000 is "outside 1..1000", not "not an integer".
    FACEDYN_ASSIGN_OR_RETURN(const int64_t repeats, node.Get<int64_t>("repeats"));
    if (repeats < 1 || repeats > kMaxRepeats) {
      return node.Error("repeats", fmt::format("{} is outside 1..{}", repeats, kMaxRepeats));
    }
    step->repeats = static_cast<int>(repeats);
  }
  step->line = node.line();
  return Status::Ok();
}

const std::vector<std::string> kStepFields = {"hz",     "settle_timeout_s", "settle_s",
                                              "hold_s", "prompt",           "repeats"};

}  // namespace

int64_t SweepScript::InstanceCount() const {
  int64_t count = 0;
  for (const SweepStep& step : steps) count += step.repeats;
  return count;
}

double SweepScript::MinimumDurationS() const {
  double total = 0.0;
  for (const SweepStep& step : steps) total += step.repeats * (step.settle_s + step.hold_s);
  return total;
}

Status SweepScript::CheckAgainst(const RigConfig& rig) const {
  // ParseSweepScript enforces this; a script built in code must too (Expand indexes by int).
  if (InstanceCount() > kMaxInstances) {
    return InvalidArgumentError(
        fmt::format("{}: {} step instances is more than the {} a sweep may have", source_path,
                    InstanceCount(), kMaxInstances));
  }
  for (size_t i = 0; i < steps.size(); ++i) {
    const SweepStep& step = steps[i];
    const RigLimits& l = rig.limits;
    if (!std::isfinite(step.hz) || step.hz < l.min_hz || step.hz > l.max_hz ||
        step.hz > l.absolute_max_hz) {
      return InvalidArgumentError(
          fmt::format("{}:{}: field 'steps[{}].hz': {} Hz is outside the rig {}'s "
                      "limits.min_hz..max_hz {}..{} Hz",
                      source_path, step.line, i, step.hz, rig.name, l.min_hz,
                      std::min(l.max_hz, l.absolute_max_hz)));
    }
  }
  return Status::Ok();
}

StatusOr<SweepScript> LoadSweepScript(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(path));
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::Parse(text, path));
  return ParseSweepScript(root, DirectoryOf(path), Fnv1a64(text));
}

StatusOr<SweepScript> ParseSweepScript(const ConfigNode& root, const std::string& base_dir,
                                       uint64_t text_hash) {
  if (!root.IsMap()) return root.Error("a sweep script must be a map");
  FACEDYN_RETURN_IF_ERROR(
      CheckKnownFields(root, {"name", "description", "rig", "defaults", "steps", "grid"}));
  SweepScript script;
  script.source_path = root.source();
  script.text_hash = text_hash;
  FACEDYN_ASSIGN_OR_RETURN(script.name, root.Get<std::string>("name"));
  FACEDYN_ASSIGN_OR_RETURN(script.description, root.GetOr<std::string>("description", ""));
  if (root.Has("rig")) {
    FACEDYN_ASSIGN_OR_RETURN(const std::string rig, root.Get<std::string>("rig"));
    script.rig_path = rig.empty() || rig[0] == '/' ? rig : base_dir + "/" + rig;
  }
  SweepStep defaults;
  if (root.Has("defaults")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, root.Child("defaults"));
    std::vector<std::string> allowed(kStepFields.begin() + 1, kStepFields.end());
    FACEDYN_RETURN_IF_ERROR(CheckKnownFields(node, allowed));
    FACEDYN_RETURN_IF_ERROR(ReadStepFields(node, /*hz_required=*/false, &defaults));
  }
  if (!root.Has("steps") && !root.Has("grid")) {
    return root.Error("a sweep needs 'steps' (a list) or 'grid' (frequencies x prompts)");
  }
  // Step instances so far; every addition is checked against the cap before anything is
  // appended, and each term is at most kMaxInstances * kMaxRepeats, so int64 cannot wrap.
  int64_t instances = 0;
  if (root.Has("steps")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode steps, root.Child("steps"));
    if (!steps.IsSequence() || steps.size() == 0)
      return steps.Error("expected a non-empty list of steps");
    for (size_t i = 0; i < steps.size(); ++i) {
      FACEDYN_ASSIGN_OR_RETURN(const ConfigNode node, steps.At(i));
      FACEDYN_RETURN_IF_ERROR(CheckKnownFields(node, kStepFields));
      SweepStep step = defaults;
      FACEDYN_RETURN_IF_ERROR(ReadStepFields(node, /*hz_required=*/true, &step));
      instances += step.repeats;
      if (instances > kMaxInstances) {
        return node.Error("repeats",
                          fmt::format("{} repeats bring the sweep to {} step instances, more than "
                                      "the {} a sweep may have",
                                      step.repeats, instances, kMaxInstances));
      }
      script.steps.push_back(step);
    }
  }
  if (root.Has("grid")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode grid, root.Child("grid"));
    std::vector<std::string> allowed = {"frequencies_hz", "prompts", "order"};
    allowed.insert(allowed.end(), kStepFields.begin() + 1, kStepFields.end());
    allowed.erase(std::find(allowed.begin(), allowed.end(), "prompt"));
    FACEDYN_RETURN_IF_ERROR(CheckKnownFields(grid, allowed));
    SweepStep cell = defaults;
    FACEDYN_RETURN_IF_ERROR(ReadStepFields(grid, /*hz_required=*/false, &cell));
    FACEDYN_ASSIGN_OR_RETURN(const std::vector<double> frequencies,
                             grid.Get<std::vector<double>>("frequencies_hz"));
    if (frequencies.empty())
      return grid.Error("frequencies_hz", "must list at least one frequency");
    std::vector<std::string> prompts = {""};
    if (grid.Has("prompts")) {
      FACEDYN_ASSIGN_OR_RETURN(prompts, grid.Get<std::vector<std::string>>("prompts"));
      if (prompts.empty())
        return grid.Error("prompts", "must list at least one prompt (or leave it out)");
    }
    FACEDYN_ASSIGN_OR_RETURN(const std::string order,
                             grid.GetOr<std::string>("order", "prompt_major"));
    if (order != "prompt_major" && order != "frequency_major") {
      return grid.Error("order", fmt::format("'{}' is not prompt_major or frequency_major", order));
    }
    // Count before expanding: cells by division (no product of list sizes can wrap), then
    // instances, each bounded before the next multiplication.
    const int64_t room = kMaxInstances - instances;
    const bool too_many_cells = frequencies.size() > static_cast<size_t>(room) / prompts.size();
    const int64_t cells =
        too_many_cells ? 0 : static_cast<int64_t>(frequencies.size() * prompts.size());
    if (too_many_cells || cells * cell.repeats > room) {
      const std::string total = too_many_cells ? "more than " + std::to_string(room)
                                               : std::to_string(cells * cell.repeats);
      return grid.Error(fmt::format(
          "{} frequencies_hz x {} prompts x {} repeats is {} step instances{}; a sweep may have "
          "at most {}",
          frequencies.size(), prompts.size(), cell.repeats, total,
          instances > 0 ? fmt::format(" after the {} of 'steps'", instances) : "", kMaxInstances));
    }
    instances += cells * cell.repeats;
    const bool prompt_major = order == "prompt_major";
    const size_t outer = prompt_major ? prompts.size() : frequencies.size();
    const size_t inner = prompt_major ? frequencies.size() : prompts.size();
    for (size_t a = 0; a < outer; ++a) {
      for (size_t b = 0; b < inner; ++b) {
        SweepStep step = cell;
        step.hz = frequencies[prompt_major ? b : a];
        step.prompt = prompts[prompt_major ? a : b];
        script.steps.push_back(step);
      }
    }
  }
  FACEDYN_CHECK(script.InstanceCount() == instances, "sweep instance count drifted");
  // Frequencies must at least be numbers in a plausible range without the rig; CheckAgainst
  // applies the rig's limits.
  for (size_t i = 0; i < script.steps.size(); ++i) {
    if (!(script.steps[i].hz > 0.0) || !std::isfinite(script.steps[i].hz)) {
      return InvalidArgumentError(
          fmt::format("{}:{}: field 'steps[{}].hz': {} is not a positive frequency",
                      script.source_path, script.steps[i].line, i, script.steps[i].hz));
    }
  }
  return script;
}

Status SweepOptions::Check() const {
  if (session_dir.empty()) return InvalidArgumentError("--session: must name a folder");
  return Status::Ok();
}

Json SweepResult::ToJson() const {
  Json json;
  json["log"] = log_path;
  json["skipped_on_resume"] = skipped;
  Json steps_json = Json::array();
  for (const SweepStepResult& s : steps) {
    Json step;
    step["instance"] = s.instance;
    step["target_hz"] = s.target_hz;
    step["prompt"] = s.prompt;
    step["hold"] = s.hold.ToJson();
    step["this_run"] = s.this_run;
    steps_json.push_back(step);
  }
  json["steps"] = steps_json;
  json["exposure"] = exposure;
  return json;
}

namespace {

std::vector<SweepStepInfo> Expand(const SweepScript& script) {
  std::vector<SweepStepInfo> instances;
  // CheckAgainst (run before this) caps the count far below INT_MAX.
  const int count = static_cast<int>(script.InstanceCount());
  for (size_t i = 0; i < script.steps.size(); ++i) {
    for (int r = 0; r < script.steps[i].repeats; ++r) {
      SweepStepInfo info;
      info.instance = static_cast<int>(instances.size());
      info.instance_count = count;
      info.step = static_cast<int>(i);
      info.repeat = r;
      info.spec = script.steps[i];
      instances.push_back(info);
    }
  }
  return instances;
}

}  // namespace

StatusOr<SweepResult> RunSweep(const SweepScript& script, const RigConfig& rig,
                               const SweepOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_RETURN_IF_ERROR(script.CheckAgainst(rig));  // before anything moves
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(options.session_dir));
  SweepResult result;
  result.log_path = JoinPath(options.session_dir, kLogName);
  result.summary_path = JoinPath(options.session_dir, kSummaryName);
  const std::vector<SweepStepInfo> instances = Expand(script);

  PriorSweep prior;
  const bool has_log = FileExists(result.log_path);
  if (options.resume) {
    if (!has_log) {
      return NotFoundError(fmt::format(
          "--resume: {} does not exist; start the sweep without --resume", result.log_path));
    }
    FACEDYN_ASSIGN_OR_RETURN(
        prior, ReadPriorSweep(result.log_path, script, static_cast<int>(instances.size())));
  } else if (has_log) {
    return FailedPreconditionError(fmt::format(
        "{} already exists: continue that session with --resume, or choose a new --session",
        result.log_path));
  }

  FACEDYN_ASSIGN_OR_RETURN(auto log, SessionLog::Open(result.log_path, prior.last_t_ns));
  if (options.resume && prior.started) {
    log->Write("resume", {{"done", prior.done.size()},
                          {"interrupted_instance", prior.interrupted},
                          {"finished", prior.finished}});
  } else {
    log->Write("sweep_start", {{"script", script.source_path},
                               {"name", script.name},
                               {"script_hash", fmt::format("{:016x}", script.text_hash)},
                               {"instances", instances.size()},
                               {"rig", rig.name}});
  }
  result.skipped = static_cast<int>(prior.done.size());

  const bool all_done = prior.done.size() == instances.size();
  if (!all_done) {
    FACEDYN_ASSIGN_OR_RETURN(auto supervisor,
                             RigSupervisor::Connect(rig, log.get(), options.stop_requested));
    supervisor->exposure().Restore(prior.vibrating_s, prior.dose_m2_s3, prior.peak_rms_m_s2);
    // A failure anywhere below ramps to stop inside the supervisor; the step stays undone.
    auto fail = [&](const SweepStepInfo* info, const Status& error) {
      log->Write("sweep_aborted",
                 {{"instance", info ? info->instance : -1}, {"reason", error.message()}});
      return error;
    };
    const Status armed = supervisor->Arm();
    if (!armed.ok()) return fail(nullptr, armed);
    for (const SweepStepInfo& info : instances) {
      if (prior.done.count(info.instance)) continue;
      const SweepStep& spec = info.spec;
      if (options.resume && options.hooks.already_done && options.hooks.already_done(info)) {
        log->Write("step_done", {{"instance", info.instance},
                                 {"step", info.step},
                                 {"repeat", info.repeat},
                                 {"hz", spec.hz},
                                 {"prompt", spec.prompt},
                                 {"recovered", true},
                                 {"exposure", supervisor->exposure().ToJson()}});
        SweepStepResult recovered;
        recovered.instance = info.instance;
        recovered.target_hz = spec.hz;
        recovered.prompt = spec.prompt;
        prior.done[info.instance] = recovered;
        continue;
      }
      log->Write("step_start", {{"instance", info.instance},
                                {"step", info.step},
                                {"repeat", info.repeat},
                                {"hz", spec.hz},
                                {"prompt", spec.prompt},
                                {"hold_s", spec.hold_s}});
      if (options.print_prompts) {
        std::printf("[%d/%d] %.2f Hz%s%s\n", info.instance + 1, info.instance_count, spec.hz,
                    spec.prompt.empty() ? "" : "  hold: ", spec.prompt.c_str());
        std::fflush(stdout);
      }
      Status status = supervisor->SetTargetHz(spec.hz);
      if (status.ok()) status = supervisor->WaitSettled(spec.settle_timeout_s);
      if (status.ok() && spec.settle_s > 0.0) status = supervisor->Hold(spec.settle_s).status();
      if (status.ok() && options.hooks.on_hold_start) {
        status = options.hooks.on_hold_start(info).WithContext(
            fmt::format("step {} hook", info.instance));
      }
      StatusOr<HoldSummary> hold = InternalError("step not held");
      if (!status.ok()) {
        hold = status;
      } else if (options.hooks.during_hold) {
        const SupervisedWork supervised =
            HoldDuring(supervisor.get(), spec.hold_s, options.hooks.max_hold_s,
                       [&](const std::atomic<bool>& abort) {
                         HoldWork work;
                         work.abort = &abort;
                         work.platform = [&supervisor] { return supervisor->Snapshot(); };
                         return options.hooks.during_hold(info, work);
                       });
        const Status work =
            supervised.work_status.WithContext(fmt::format("step {} hook", info.instance));
        if (!supervised.hold_status.ok()) {
          // The platform's verdict first; what it did to the work is logged beside it.
          hold = supervised.hold_status;
          if (!supervised.work_status.ok())
            log->Write("step_work", {{"instance", info.instance}, {"result", work.message()}});
        } else if (!supervised.work_status.ok()) {
          hold = work;
        } else {
          hold = supervised.hold;
        }
      } else {
        hold = supervisor->Hold(spec.hold_s);
      }
      if (hold.ok() && options.hooks.on_hold_end) {
        status = options.hooks.on_hold_end(info, *hold)
                     .WithContext(fmt::format("step {} hook", info.instance));
        if (!status.ok()) hold = status;
      }
      if (!hold.ok()) {
        if (supervisor->state() != RigState::kStopped &&
            supervisor->state() != RigState::kLinkLost &&
            supervisor->state() != RigState::kFaulted) {
          (void)supervisor->RampToStop(hold.status().message());
        }
        return fail(&info, hold.status());
      }
      log->Write("step_done", {{"instance", info.instance},
                               {"step", info.step},
                               {"repeat", info.repeat},
                               {"hz", spec.hz},
                               {"prompt", spec.prompt},
                               {"hold", hold->ToJson()},
                               {"exposure", supervisor->exposure().ToJson()}});
      SweepStepResult step_result;
      step_result.instance = info.instance;
      step_result.target_hz = spec.hz;
      step_result.prompt = spec.prompt;
      step_result.hold = *hold;
      step_result.this_run = true;
      prior.done[info.instance] = step_result;
    }
    FACEDYN_RETURN_IF_ERROR(supervisor->RampToStop("sweep done"));
    result.exposure = supervisor->exposure().ToJson();
    FACEDYN_RETURN_IF_ERROR(supervisor->Close());
  } else {
    VibrationExposure exposure(rig.amplitude_mm);
    exposure.Restore(prior.vibrating_s, prior.dose_m2_s3, prior.peak_rms_m_s2);
    result.exposure = exposure.ToJson();
  }
  for (const auto& [instance, step] : prior.done) result.steps.push_back(step);
  if (!prior.finished)
    log->Write("sweep_done", {{"instances", instances.size()}, {"exposure", result.exposure}});
  FACEDYN_RETURN_IF_ERROR(log->status());
  Json summary = result.ToJson();
  summary["sweep"] = script.name;
  summary["rig"] = rig.name;
  FACEDYN_RETURN_IF_ERROR(WriteJsonFile(result.summary_path, summary));
  return result;
}

}  // namespace facedyn::rig
