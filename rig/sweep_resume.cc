#include "rig/sweep_resume.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include "core/json_io.h"
#include "rig/session_log.h"

namespace facedyn::rig {
namespace {

// A JSON number that must be finite and >= 0 (exposure, hold statistics).
double NonNegative(const Json& record, const char* key, double fallback) {
  if (!record.contains(key)) return fallback;
  const double value = record.at(key).get<double>();  // type_error when not a number
  if (!std::isfinite(value) || value < 0.0) {
    throw std::out_of_range(fmt::format("'{}' is {}, not a finite value >= 0", key, value));
  }
  return value;
}

// An integer field. It must be a JSON integer: nlohmann converts a float such as 8.9e74 to
// int64 with a plain cast, which is undefined behaviour out of range (fuzz/sweep_resume).
int64_t IntegerField(const Json& record, const char* key, int64_t fallback) {
  if (!record.contains(key)) return fallback;
  const Json& value = record.at(key);
  if (value.is_number_unsigned() &&
      value.get<uint64_t>() > uint64_t(std::numeric_limits<int64_t>::max())) {
    throw std::out_of_range(fmt::format("'{}' is {}, beyond int64", key, value.get<uint64_t>()));
  }
  if (!value.is_number_integer()) {
    throw std::out_of_range(fmt::format("'{}' is {}, not an integer", key,
                                        value.dump(-1, ' ', false, kJsonReplaceInvalidUtf8)));
  }
  return value.get<int64_t>();
}

HoldSummary HoldFromJson(const Json& json) {
  if (!json.is_object()) throw std::out_of_range("'hold' is not an object");
  HoldSummary hold;
  hold.seconds = NonNegative(json, "seconds", 0.0);
  const int64_t samples = IntegerField(json, "samples", 0);
  if (samples < 0 || samples > std::numeric_limits<int>::max()) {
    throw std::out_of_range(fmt::format("'samples' is {}, not a count", samples));
  }
  hold.samples = static_cast<int>(samples);
  hold.target_hz = NonNegative(json, "target_hz", 0.0);
  hold.mean_measured_hz = NonNegative(json, "mean_measured_hz", 0.0);
  hold.max_abs_error_hz = NonNegative(json, "max_abs_error_hz", 0.0);
  hold.rms_error_hz = NonNegative(json, "rms_error_hz", 0.0);
  return hold;
}

int Instance(const Json& record, int instance_count) {
  if (!record.contains("instance")) throw std::out_of_range("no 'instance'");
  const int64_t instance = IntegerField(record, "instance", -1);
  if (instance < 0 || instance >= instance_count) {
    throw std::out_of_range(fmt::format("step instance {} is not in the script ({} instances)",
                                        instance, instance_count));
  }
  return static_cast<int>(instance);
}

}  // namespace

StatusOr<PriorSweep> ReadPriorSweep(const std::string& log_path, const SweepScript& script,
                                    int instance_count) {
  PriorSweep prior;
  bool truncated = false;
  FACEDYN_ASSIGN_OR_RETURN(const std::vector<Json> records, ReadSessionLog(log_path, &truncated));
  if (truncated)
    spdlog::warn("{}: the last line was cut off (crash mid-write); ignoring it", log_path);
  const std::string hash = fmt::format("{:016x}", script.text_hash);
  size_t record_number = 0;
  for (const Json& r : records) {
    ++record_number;
    // A record with a missing, mistyped or out-of-range field (a hand-edited or foreign log) is
    // a clear error naming the record, never an exception escaping the resume.
    try {
      const std::string event = r.at("event").get<std::string>();
      prior.last_t_ns = std::max(prior.last_t_ns, IntegerField(r, "t_ns", 0));
      if (r.contains("vibrating_s") && r.contains("dose_m2_s3")) {
        prior.vibrating_s = std::max(prior.vibrating_s, NonNegative(r, "vibrating_s", 0.0));
        prior.dose_m2_s3 = std::max(prior.dose_m2_s3, NonNegative(r, "dose_m2_s3", 0.0));
      }
      if (r.contains("exposure") && r.at("exposure").is_object()) {
        prior.peak_rms_m_s2 =
            std::max(prior.peak_rms_m_s2, NonNegative(r.at("exposure"), "peak_rms_m_s2", 0.0));
      }
      if (event == "sweep_start") {
        if (r.value("script_hash", std::string()) != hash) {
          return FailedPreconditionError(fmt::format(
              "{}: this session was started with a different sweep script ({} hash {}, now {}); "
              "resume with the original file or start a new --session",
              log_path, r.value("script", std::string("?")),
              r.value("script_hash", std::string("?")), hash));
        }
        prior.started = true;
      } else if (event == "step_start") {
        prior.interrupted = Instance(r, instance_count);
      } else if (event == "step_done") {
        const int instance = Instance(r, instance_count);
        if (prior.done.count(instance)) {
          return DataLossError(
              fmt::format("{}: step instance {} is marked done twice", log_path, instance));
        }
        SweepStepResult result;
        result.instance = instance;
        result.target_hz = r.value("hz", 0.0);
        result.prompt = r.value("prompt", std::string());
        result.hold = HoldFromJson(r.value("hold", Json::object()));
        prior.done[instance] = result;
        if (prior.interrupted == instance) prior.interrupted = -1;
      } else if (event == "sweep_done") {
        prior.finished = true;
      }
    } catch (const std::exception& e) {  // Json::exception or the range checks above
      return DataLossError(fmt::format("{}: record {} is not a valid sweep record: {}", log_path,
                                       record_number, e.what()));
    }
  }
  // A run killed between creating the log and its first record left nothing to resume: the
  // sweep starts from its beginning.
  if (!prior.started && !records.empty()) {
    return FailedPreconditionError(
        fmt::format("{}: no sweep_start record: not a sweep session log", log_path));
  }
  return prior;
}

}  // namespace facedyn::rig
