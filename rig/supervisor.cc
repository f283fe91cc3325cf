#include "rig/supervisor.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <thread>

namespace facedyn::rig {
namespace {

using Clock = std::chrono::steady_clock;

constexpr double kStartGraceS = 1.5;  // a drive may take this long to report "running"
// Stop commands sent (each waiting up to safety.stop_timeout_s) before a stop is given up.
constexpr int kStopAttempts = 3;

Json StatusJson(const Status& status) {
  if (status.ok()) return "ok";
  return status.message();
}

}  // namespace

const char* RigStateName(RigState state) {
  switch (state) {
    case RigState::kIdle:
      return "idle";
    case RigState::kRamping:
      return "ramping";
    case RigState::kSettling:
      return "settling";
    case RigState::kSettled:
      return "settled";
    case RigState::kStopping:
      return "stopping";
    case RigState::kStopped:
      return "stopped";
    case RigState::kFaulted:
      return "faulted";
    case RigState::kLinkLost:
      return "link_lost";
  }
  return "?";
}

Json PlatformReading::ToJson() const {
  Json json;
  json["time_s"] = time_s;
  json["running"] = running;
  json["faulted"] = faulted;
  json["fault_code"] = fault_code;
  json["fault_text"] = fault_text;
  json["output_hz"] = output_hz;
  json["measured_hz"] = measured_hz;
  json["target_hz"] = target_hz;
  json["commanded_hz"] = commanded_hz;
  json["correction_hz"] = correction_hz;
  json["motor_setpoint_hz"] = motor_setpoint_hz;
  json["settled"] = settled;
  return json;
}

Json HoldSummary::ToJson() const {
  Json json;
  json["seconds"] = seconds;
  json["samples"] = samples;
  json["target_hz"] = target_hz;
  json["mean_measured_hz"] = mean_measured_hz;
  json["max_abs_error_hz"] = max_abs_error_hz;
  json["rms_error_hz"] = rms_error_hz;
  return json;
}

RigSupervisor::RigSupervisor(const RigConfig& config, SessionLog* log,
                             const std::atomic<bool>* stop_requested)
    : config_(config),
      log_(log),
      stop_requested_(stop_requested),
      model_(config.platform),
      trim_(config.trim),
      settle_(config.settle),
      exposure_(config.amplitude_mm),
      start_(Clock::now()),
      last_tick_(start_),
      last_exposure_(start_) {}

StatusOr<std::unique_ptr<RigSupervisor>> RigSupervisor::Connect(
    const RigConfig& config, SessionLog* log, const std::atomic<bool>* stop_requested) {
  FACEDYN_RETURN_IF_ERROR(config.Check());
  std::unique_ptr<RigSupervisor> supervisor(new RigSupervisor(config, log, stop_requested));
  auto transport = ModbusTransport::Open(config.transport);
  if (!transport.ok()) {
    if (log)
      log->Write("connect", {{"rig", config.name}, {"result", transport.status().message()}});
    return transport.status().WithContext(fmt::format("rig {}", config.name));
  }
  supervisor->transport_ = std::move(transport).value();
  supervisor->client_ = std::make_unique<DriveClient>(supervisor->transport_.get(), config.profile,
                                                      config.MotorLimits());
  if (log) {
    log->Write("connect", {{"rig", config.name},
                           {"config", config.source_path},
                           {"profile", config.profile.name},
                           {"transport", config.transport.Describe()},
                           {"result", "ok"}});
  }
  return supervisor;
}

RigSupervisor::~RigSupervisor() {
  const Status closed = Close();
  if (!closed.ok()) spdlog::error("rig {}: {}", config_.name, closed.message());
}

double RigSupervisor::ElapsedS() const {
  return std::chrono::duration<double>(Clock::now() - start_).count();
}

void RigSupervisor::SetState(RigState state, const std::string& reason) {
  const bool not_moving = state == RigState::kStopping || state == RigState::kStopped ||
                          state == RigState::kFaulted || state == RigState::kLinkLost;
  if (not_moving && notify_on_stop_ != nullptr) notify_on_stop_->store(true);
  if (state == state_) return;
  if (log_)
    log_->Write("state",
                {{"from", RigStateName(state_)}, {"to", RigStateName(state)}, {"reason", reason}});
  spdlog::debug("rig {}: {} -> {} ({})", config_.name, RigStateName(state_), RigStateName(state),
                reason);
  state_ = state;
  Publish();
}

void RigSupervisor::Publish() {
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  snapshot_.reading = last_;
  snapshot_.state = state_;
}

PlatformSnapshot RigSupervisor::Snapshot() const {
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  return snapshot_;
}

void RigSupervisor::AccountExposure(double platform_hz) {
  const auto now = Clock::now();
  exposure_.Add(platform_hz, std::chrono::duration<double>(now - last_exposure_).count());
  last_exposure_ = now;
}

void RigSupervisor::LogCommand(const std::string& what, Json fields, const Status& result) {
  if (!log_) return;
  fields["command"] = what;
  fields["result"] = StatusJson(result);
  log_->Write("command", std::move(fields));
}

Status RigSupervisor::WriteWatchdog(double seconds) {
  const auto& watchdog = config_.profile.comm_watchdog;
  if (!watchdog || !watchdog->register_address) return Status::Ok();
  const double counts = std::round(seconds * watchdog->counts_per_s);
  if (counts < 0 || counts > 65535 || (watchdog->max_s > 0.0 && seconds > watchdog->max_s)) {
    return InvalidArgumentError(
        fmt::format("safety.comm_watchdog_s: {} s does not fit {} (max {} s)", seconds,
                    watchdog->parameter, watchdog->max_s));
  }
  const Status written =
      transport_->WriteRegister(*watchdog->register_address, static_cast<uint16_t>(counts));
  LogCommand("comm_watchdog",
             {{"register", *watchdog->register_address},
              {"value", counts},
              {"seconds", seconds},
              {"parameter", watchdog->parameter}},
             written);
  return written.WithContext(fmt::format("drive {} {}", config_.profile.name, watchdog->parameter));
}

Status RigSupervisor::Arm() {
  PlatformReading reading;
  FACEDYN_RETURN_IF_ERROR(ReadPlatform(&reading));
  last_ = reading;  // a platform still turning (e.g. after `rig set --detach`) ramps from here
  last_exposure_ = Clock::now();  // exposure before this session is not ours to count
  Publish();
  standstill_confirmed_ = reading.output_hz == 0.0 && !reading.running;
  if (log_) log_->Write("reply", reading.ToJson());
  if (reading.faulted) {
    SetState(RigState::kFaulted, reading.fault_text);
    return FailedPreconditionError(fmt::format(
        "rig {}: the drive is tripped: fault {}; check the platform, then acknowledge with "
        "`facedyn rig reset --config {}`",
        config_.name, reading.fault_text, config_.source_path));
  }
  const double watchdog_s = config_.safety.comm_watchdog_s;
  const auto& watchdog = config_.profile.comm_watchdog;
  if (watchdog_s > 0.0) {
    if (watchdog && watchdog->register_address) {
      FACEDYN_RETURN_IF_ERROR(WriteWatchdog(watchdog_s));
      watchdog_armed_ = true;
    } else {
      const std::string where =
          watchdog ? watchdog->parameter : std::string("its comm-loss parameter");
      spdlog::warn(
          "rig {}: drive profile {} cannot set the comm watchdog over Modbus: set {} on the "
          "drive to {} s",
          config_.name, config_.profile.name, where, watchdog_s);
      if (log_)
        log_->Write("warning",
                    {{"message", fmt::format("comm watchdog not set over Modbus; set {}", where)}});
    }
  }
  if (log_) log_->Write("armed", {{"comm_watchdog_s", watchdog_armed_ ? watchdog_s : 0.0}});
  return Status::Ok();
}

Status RigSupervisor::ReadPlatform(PlatformReading* reading) {
  auto status = client_->ReadStatus();
  if (!status.ok()) return status.status();
  reading->time_s = ElapsedS();
  reading->running = status->running;
  reading->faulted = status->faulted;
  reading->fault_code = status->fault_code;
  reading->fault_text = status->fault_text;
  reading->output_hz = status->output_hz;
  if (config_.feedback == "sensor") {
    auto words = transport_->ReadRegisters(*config_.profile.oscillation_register, 1);
    if (!words.ok())
      return words.status().WithContext(
          fmt::format("drive {} oscillation sensor", config_.profile.name));
    reading->measured_hz = config_.profile.oscillation_scaling.RegisterToHz((*words)[0]);
  } else {
    reading->measured_hz = model_.PlatformHzFor(status->output_hz);
  }
  reading->target_hz = target_hz_;
  reading->commanded_hz = commanded_hz_;
  reading->correction_hz = trim_.correction_hz();
  reading->motor_setpoint_hz = std::max(0.0, written_motor_hz_);
  return Status::Ok();
}

StatusOr<PlatformReading> RigSupervisor::ReadOnce() {
  PlatformReading reading;
  const Status read = ReadPlatform(&reading);
  if (log_) {
    Json fields = read.ok() ? reading.ToJson() : Json::object();
    fields["result"] = StatusJson(read);
    log_->Write("reply", std::move(fields));
  }
  if (!read.ok()) return read.WithContext(fmt::format("rig {}", config_.name));
  last_ = reading;
  if (reading.faulted) SetState(RigState::kFaulted, reading.fault_text);
  return reading;
}

Status RigSupervisor::WriteMotorSetpoint(double motor_hz) {
  const Status written = client_->SetFrequencyHz(motor_hz);
  LogCommand("setpoint",
             {{"register", config_.profile.setpoint_register},
              {"motor_hz", motor_hz},
              {"platform_hz", commanded_hz_ + trim_.correction_hz()}},
             written);
  if (written.ok()) written_motor_hz_ = motor_hz;
  return written;
}

Status RigSupervisor::SetTargetHz(double hz) {
  const RigLimits& limits = config_.limits;
  Status refused;
  if (!std::isfinite(hz)) {
    refused = InvalidArgumentError(fmt::format("hz: {} is not a number", hz));
  } else if (hz > limits.absolute_max_hz) {
    refused = InvalidArgumentError(
        fmt::format("hz: {} Hz is above limits.absolute_max_hz {} Hz of rig {}", hz,
                    limits.absolute_max_hz, config_.name));
  } else if (hz < limits.min_hz || hz > limits.max_hz) {
    refused = InvalidArgumentError(
        fmt::format("hz: {} Hz is outside limits.min_hz..max_hz {}..{} Hz of rig {}", hz,
                    limits.min_hz, limits.max_hz, config_.name));
  }
  if (!refused.ok()) {
    if (log_)
      log_->Write("refused", {{"hz", std::isfinite(hz) ? Json(hz) : Json(nullptr)},
                              {"reason", refused.message()}});
    return refused;
  }
  if (log_) log_->Write("target", {{"hz", hz}});
  const bool was_moving =
      state_ == RigState::kRamping || state_ == RigState::kSettling || state_ == RigState::kSettled;
  target_hz_ = hz;
  standstill_confirmed_ = false;
  settle_.Restart();
  jumped_for_target_ = false;
  at_speed_since_s_ = -1.0;
  if (!was_moving) {
    // From standstill the drive's own acceleration ramp takes the motor up to the first
    // setpoint; from there the supervisor's ramp-rate limit governs every change.
    commanded_hz_ =
        std::min(hz, std::max(limits.min_hz, std::min(last_.measured_hz, limits.max_hz)));
    trim_.Reset();
    FACEDYN_RETURN_IF_ERROR(FailAndStop(WriteMotorSetpoint(model_.MotorHzFor(commanded_hz_))));
    const Status started = client_->Start();
    LogCommand(
        "run",
        {{"register", config_.profile.command_register}, {"value", config_.profile.run_value}},
        started);
    FACEDYN_RETURN_IF_ERROR(FailAndStop(started));
    run_commanded_at_s_ = ElapsedS();
  }
  last_tick_ = Clock::now();
  SetState(RigState::kRamping, fmt::format("target {} Hz", hz));
  return Status::Ok();
}

Status RigSupervisor::LinkLost(const Status& error) {
  SetState(RigState::kLinkLost, error.message());
  standstill_confirmed_ = false;
  std::string fallback = WatchdogFallback();
  // One stop attempt: the link may come back for it.
  const Status stop = client_->Stop();
  LogCommand("stop",
             {{"register", config_.profile.command_register},
              {"value", config_.profile.stop_value},
              {"reason", "link lost"}},
             stop);
  if (stop.ok()) fallback = "a stop command got through after it";
  if (log_) log_->Write("link_lost", {{"error", error.message()}, {"fallback", fallback}});
  return UnavailableError(fmt::format("rig {}: link to the drive lost ({}); {}", config_.name,
                                      error.message(), fallback));
}

Status RigSupervisor::FailAndStop(const Status& error) {
  if (error.ok()) return error;
  if (state_ == RigState::kLinkLost || state_ == RigState::kStopping) return error;
  const Status stopped = RampToStop(error.message());
  if (!stopped.ok())
    return error.WithContext(fmt::format("also, ramp to stop failed: {}", stopped.message()));
  return error;
}

Status RigSupervisor::Tick() {
  if (StopRequested())
    return AbortedError(fmt::format("rig {}: stop requested (signal)", config_.name));
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(config_.safety.control_period_s));
  const auto next = last_tick_ + period;
  while (Clock::now() < next) {
    if (StopRequested())
      return AbortedError(fmt::format("rig {}: stop requested (signal)", config_.name));
    std::this_thread::sleep_until(std::min(next, Clock::now() + std::chrono::milliseconds(10)));
  }
  const auto now = Clock::now();
  // The ramp and the trim integrate at most 1 s per tick, so that a late tick cannot make the
  // command leap; the exposure counts all of the time (AccountExposure).
  const double dt_s = std::clamp(std::chrono::duration<double>(now - last_tick_).count(), 0.0, 1.0);
  last_tick_ = now;

  PlatformReading reading;
  const Status read = ReadPlatform(&reading);
  const TransportStats stats = transport_->stats();
  if (log_ && (stats.retries != logged_stats_.retries || stats.failures != logged_stats_.failures ||
               stats.reconnects != logged_stats_.reconnects)) {
    // Retried timeouts and corrupt replies (CRC errors) are visible in the journal.
    log_->Write("link", {{"retries", stats.retries},
                         {"failures", stats.failures},
                         {"reconnects", stats.reconnects},
                         {"transactions", stats.transactions}});
  }
  logged_stats_ = stats;
  if (!read.ok()) {
    if (log_) log_->Write("reply", {{"result", read.message()}});
    // Only a read that got no answer means the link is lost. A drive that answered "busy"
    // more often than the transport retries (or refused the read) is alive and listening:
    // it gets a controlled ramp to stop, whose stop is retried until standstill, instead of
    // the single stop attempt of a lost link.
    if (read.code() != StatusCode::kUnavailable) {
      return FailAndStop(read.WithContext(fmt::format("rig {}: status read", config_.name)));
    }
    return LinkLost(read);
  }
  last_ = reading;
  if (reading.faulted) {
    SetState(RigState::kFaulted, reading.fault_text);
    if (log_) log_->Write("reply", reading.ToJson());
    // Drop the run command so that acknowledging the trip later cannot restart the motor.
    const Status stop = client_->Stop();
    LogCommand("stop",
               {{"register", config_.profile.command_register},
                {"value", config_.profile.stop_value},
                {"reason", "drive tripped"}},
               stop);
    run_commanded_at_s_ = -1.0;
    target_hz_ = 0.0;
    return FailedPreconditionError(fmt::format(
        "rig {}: the drive tripped: fault {}; check the platform, then acknowledge with "
        "`facedyn rig reset --config {}`",
        config_.name, reading.fault_text, config_.source_path));
  }
  if (reading.measured_hz > config_.limits.absolute_max_hz + config_.limits.overspeed_margin_hz) {
    if (log_) log_->Write("reply", reading.ToJson());
    return FailAndStop(FailedPreconditionError(fmt::format(
        "rig {}: overspeed: the platform measures {:.3f} Hz, above limits.absolute_max_hz {} Hz + "
        "overspeed_margin_hz {} Hz",
        config_.name, reading.measured_hz, config_.limits.absolute_max_hz,
        config_.limits.overspeed_margin_hz)));
  }
  const bool moving_state =
      state_ == RigState::kRamping || state_ == RigState::kSettling || state_ == RigState::kSettled;
  if (moving_state && !reading.running && run_commanded_at_s_ >= 0.0 &&
      reading.time_s - run_commanded_at_s_ > kStartGraceS) {
    if (log_) log_->Write("reply", reading.ToJson());
    return FailAndStop(FailedPreconditionError(fmt::format(
        "rig {}: the drive stopped on its own (not running, output {:.2f} Hz) while facedyn held "
        "{} Hz: a local stop, its comm watchdog, or an interlock",
        config_.name, reading.output_hz, target_hz_)));
  }
  AccountExposure(reading.measured_hz);

  if (moving_state) {
    // Ramp-rate limit on the platform frequency.
    const double step_hz = config_.limits.max_ramp_hz_per_s * dt_s;
    commanded_hz_ = commanded_hz_ < target_hz_ ? std::min(target_hz_, commanded_hz_ + step_hz)
                                               : std::max(target_hz_, commanded_hz_ - step_hz);
    const bool ramp_done = commanded_hz_ == target_hz_;
    const double count_hz = 1.0 / config_.profile.setpoint_scaling.CountsPerHz();
    const bool at_speed = written_motor_hz_ >= 0.0 &&
                          std::abs(reading.output_hz - written_motor_hz_) <= 0.02 + count_hz;
    if (ramp_done && at_speed) {
      if (at_speed_since_s_ < 0.0) at_speed_since_s_ = reading.time_s;
    } else {
      at_speed_since_s_ = -1.0;
    }
    const bool trim_ready =
        at_speed_since_s_ >= 0.0 && reading.time_s - at_speed_since_s_ >= config_.trim.delay_s;
    if (trim_ready) {
      if (!jumped_for_target_) {
        trim_.Jump(target_hz_, reading.measured_hz);
        jumped_for_target_ = true;
        at_speed_since_s_ = -1.0;  // wait for the sensor to see the corrected speed
      } else {
        trim_.Update(target_hz_, reading.measured_hz, dt_s);
      }
    }
    if (config_.feedback == "sensor" && trim_ready) {
      // Cross-check the sensor against the drive: the overspeed check and the trim both trust
      // the sensor, so a sensor that drifts must not go unnoticed.
      const double from_output_hz = model_.PlatformHzFor(reading.output_hz);
      if (std::abs(reading.measured_hz - from_output_hz) > config_.safety.sensor_tolerance_hz) {
        if (log_) log_->Write("reply", reading.ToJson());
        return FailAndStop(FailedPreconditionError(fmt::format(
            "rig {}: the oscillation sensor reads {:.3f} Hz but the drive's output {:.3f} Hz "
            "means {:.3f} Hz on the platform model: they disagree by more than "
            "safety.sensor_tolerance_hz {} Hz; check the sensor (or platform.ratio/slip)",
            config_.name, reading.measured_hz, reading.output_hz, from_output_hz,
            config_.safety.sensor_tolerance_hz)));
      }
    }
    settle_.Update(reading.time_s, target_hz_, reading.measured_hz,
                   trim_ready && jumped_for_target_);
    if (ramp_done && state_ == RigState::kRamping) SetState(RigState::kSettling, "ramp done");
    if (settle_.settled() && state_ == RigState::kSettling) {
      SetState(RigState::kSettled, fmt::format("within {} Hz for {} s", config_.settle.tolerance_hz,
                                               config_.settle.time_s));
    }
    if (!settle_.settled() && state_ == RigState::kSettled)
      SetState(RigState::kSettling, "left the tolerance");

    // limits.absolute_max_hz caps the command itself, whatever the trim asks for. The cap
    // assumes zero slip (the rotor never outruns the drive's field while motoring), so it holds
    // whatever the true slip is, and it does not trust the sensor: a sensor that reads low can
    // only leave the platform short of its target, never above absolute_max_hz.
    const double motor_cap_hz = config_.limits.absolute_max_hz / config_.platform.ratio;
    const double motor_hz =
        std::min(model_.MotorHzFor(commanded_hz_ + trim_.correction_hz()), motor_cap_hz);
    if (std::abs(motor_hz - written_motor_hz_) >= 0.5 * count_hz) {
      const Status written = WriteMotorSetpoint(motor_hz);
      if (!written.ok()) {
        if (written.code() == StatusCode::kUnavailable) return LinkLost(written);
        return FailAndStop(written);
      }
    }
    reading.commanded_hz = commanded_hz_;
    reading.correction_hz = trim_.correction_hz();
    reading.motor_setpoint_hz = written_motor_hz_;
    reading.settled = settle_.settled();
    last_ = reading;
  }
  if (log_) {
    Json fields = reading.ToJson();
    fields["state"] = RigStateName(state_);
    fields["tick_s"] =
        std::chrono::duration<double>(now - start_).count();  // the clock the ramp used
    fields["vibrating_s"] = exposure_.vibrating_s();
    fields["dose_m2_s3"] = exposure_.dose_m2_s3();
    log_->Write("reply", std::move(fields));
  }
  Publish();
  if (log_) FACEDYN_RETURN_IF_ERROR(FailAndStop(log_->status()));
  return Status::Ok();
}

Status RigSupervisor::WaitSettled(double timeout_s) {
  const double deadline_s = ElapsedS() + timeout_s;
  while (state_ != RigState::kSettled) {
    const Status ticked = Tick();
    if (!ticked.ok()) return FailAndStop(ticked);
    if (ElapsedS() > deadline_s) {
      return FailAndStop(FailedPreconditionError(
          fmt::format("rig {}: the platform did not settle at {} Hz within {} s (measured {:.3f} "
                      "Hz, trim {:+.3f} Hz{})",
                      config_.name, target_hz_, timeout_s, last_.measured_hz, trim_.correction_hz(),
                      trim_.saturated() ? ", at its limit platform.trim.max_correction_hz" : "")));
    }
  }
  if (log_)
    log_->Write("settled", {{"target_hz", target_hz_},
                            {"measured_hz", last_.measured_hz},
                            {"correction_hz", trim_.correction_hz()}});
  return Status::Ok();
}

StatusOr<HoldSummary> RigSupervisor::Hold(double seconds) {
  return HoldWhile([seconds](double held_s) { return held_s < seconds; });
}

StatusOr<HoldSummary> RigSupervisor::HoldWhile(
    const std::function<bool(double held_s)>& keep_holding) {
  HoldSummary summary;
  summary.target_hz = target_hz_;
  const double begin_s = ElapsedS();
  double sum_hz = 0.0;
  double sum_sq_error = 0.0;
  while (keep_holding(ElapsedS() - begin_s)) {
    const Status ticked = Tick();
    if (!ticked.ok()) return FailAndStop(ticked);
    const double error_hz = last_.measured_hz - target_hz_;
    ++summary.samples;
    sum_hz += last_.measured_hz;
    sum_sq_error += error_hz * error_hz;
    summary.max_abs_error_hz = std::max(summary.max_abs_error_hz, std::abs(error_hz));
  }
  summary.seconds = ElapsedS() - begin_s;
  if (summary.samples > 0) {
    summary.mean_measured_hz = sum_hz / summary.samples;
    summary.rms_error_hz = std::sqrt(sum_sq_error / summary.samples);
  }
  if (log_) log_->Write("hold", summary.ToJson());
  return summary;
}

std::string RigSupervisor::WatchdogFallback() const {
  const auto& watchdog = config_.profile.comm_watchdog;
  if (watchdog_armed_) {
    return fmt::format(
        "the drive's comm watchdog ({}, {} s) is left armed and stops the motor once facedyn "
        "goes quiet",
        watchdog->parameter, config_.safety.comm_watchdog_s);
  }
  if (watchdog) {
    return fmt::format("the drive stops only if its {} is set on the drive: CHECK THE PLATFORM",
                       watchdog->parameter);
  }
  return "the drive has no comm watchdog known to facedyn: STOP THE PLATFORM BY HAND";
}

Status RigSupervisor::RampToStop(const std::string& reason) {
  SetState(RigState::kStopping, reason);
  target_hz_ = 0.0;
  run_commanded_at_s_ = -1.0;
  standstill_confirmed_ = false;
  // A stop is final only when the drive reports standstill. A refused stop (an exception reply
  // the transport did not clear by retrying) or one that did not reach 0 Hz within
  // safety.stop_timeout_s is sent again, kStopAttempts times in all; after that facedyn gives
  // up with the drive-side watchdog still armed (Close() disarms it only after standstill).
  std::string last_failure;
  for (int attempt = 1; attempt <= kStopAttempts; ++attempt) {
    const Status stop = client_->Stop();
    LogCommand("stop",
               {{"register", config_.profile.command_register},
                {"value", config_.profile.stop_value},
                {"reason", reason},
                {"attempt", attempt}},
               stop);
    if (!stop.ok()) {
      if (stop.code() == StatusCode::kUnavailable) return LinkLost(stop);
      last_failure = fmt::format("stop command refused: {}", stop.message());
      spdlog::warn("rig {}: {} (attempt {}/{})", config_.name, last_failure, attempt,
                   kStopAttempts);
      std::this_thread::sleep_for(std::chrono::duration<double>(config_.safety.control_period_s));
      continue;
    }
    const double deadline_s = ElapsedS() + config_.safety.stop_timeout_s;
    for (;;) {
      std::this_thread::sleep_for(std::chrono::duration<double>(config_.safety.control_period_s));
      PlatformReading reading;
      const Status read = ReadPlatform(&reading);
      if (!read.ok()) {
        if (read.code() == StatusCode::kUnavailable) return LinkLost(read);
        // Busy or refused: the drive answers, so keep polling it until the deadline, then
        // send the stop again.
        last_failure = fmt::format("status read refused: {}", read.message());
        if (ElapsedS() > deadline_s) {
          spdlog::warn("rig {}: {} (attempt {}/{})", config_.name, last_failure, attempt,
                       kStopAttempts);
          break;
        }
        continue;
      }
      AccountExposure(reading.measured_hz);
      last_tick_ = Clock::now();
      last_ = reading;
      Publish();
      if (log_) {
        Json fields = reading.ToJson();
        fields["state"] = RigStateName(state_);
        fields["vibrating_s"] = exposure_.vibrating_s();
        fields["dose_m2_s3"] = exposure_.dose_m2_s3();
        log_->Write("reply", std::move(fields));
      }
      // Standstill is the drive reporting exactly 0 Hz output (register 0), not "nearly
      // stopped".
      if (reading.output_hz == 0.0 && !reading.running) {
        standstill_confirmed_ = true;
        break;
      }
      if (ElapsedS() > deadline_s) {
        last_failure = fmt::format("still at {:.2f} Hz {} s after the stop command "
                                   "(safety.stop_timeout_s)",
                                   reading.output_hz, config_.safety.stop_timeout_s);
        spdlog::warn("rig {}: {} (attempt {}/{})", config_.name, last_failure, attempt,
                     kStopAttempts);
        break;
      }
    }
    if (standstill_confirmed_) break;
  }
  if (!standstill_confirmed_) {
    const std::string fallback = WatchdogFallback();
    if (log_)
      log_->Write("stop_unconfirmed", {{"error", last_failure},
                                       {"attempts", kStopAttempts},
                                       {"fallback", fallback}});
    return FailedPreconditionError(
        fmt::format("rig {}: the stop was not confirmed after {} attempts ({}); {}", config_.name,
                    kStopAttempts, last_failure, fallback));
  }
  commanded_hz_ = 0.0;
  written_motor_hz_ = -1.0;
  trim_.Reset();
  SetState(last_.faulted ? RigState::kFaulted : RigState::kStopped, "output at 0 Hz");
  return Status::Ok();
}

Status RigSupervisor::ResetFault() {
  const Status reset = client_->ResetFault();
  LogCommand("fault_reset", {{"register", config_.profile.fault_reset_register}}, reset);
  FACEDYN_RETURN_IF_ERROR(reset.WithContext(fmt::format("rig {}", config_.name)));
  if (state_ == RigState::kFaulted) SetState(RigState::kStopped, "fault acknowledged");
  return Status::Ok();
}

Status RigSupervisor::Close() {
  if (closed_ || !client_) return Status::Ok();
  closed_ = true;
  Status result;
  // Anything but a confirmed standstill (a move, an unconfirmed stop, a trip whose output was
  // not yet read at 0 Hz, an armed drive that was found turning) gets a stop first. A lost
  // link gets none: the drive's watchdog is the fallback there and stays armed.
  const bool unconfirmed = state_ != RigState::kIdle || watchdog_armed_;
  if (unconfirmed && !standstill_confirmed_ && state_ != RigState::kLinkLost)
    result = RampToStop("session closed");
  if (watchdog_armed_) {
    if (standstill_confirmed_ && state_ != RigState::kLinkLost) {
      // A stopped drive with an armed comm watchdog would trip once facedyn goes quiet.
      const Status disarmed = WriteWatchdog(0.0);
      if (result.ok()) result = disarmed;
      if (disarmed.ok()) watchdog_armed_ = false;
    } else if (result.ok()) {
      result = FailedPreconditionError(
          fmt::format("rig {}: closed without a confirmed standstill ({}); {}", config_.name,
                      RigStateName(state_), WatchdogFallback()));
    }
  }
  if (log_)
    log_->Write("close", {{"state", RigStateName(state_)},
                          {"standstill_confirmed", standstill_confirmed_},
                          {"watchdog_armed", watchdog_armed_},
                          {"exposure", exposure_.ToJson()}});
  return result;
}

Status RigSupervisor::Detach() {
  if (watchdog_armed_) {
    FACEDYN_RETURN_IF_ERROR(WriteWatchdog(0.0));
    watchdog_armed_ = false;
  }
  if (log_)
    log_->Write("detach", {{"target_hz", target_hz_}, {"motor_setpoint_hz", written_motor_hz_}});
  closed_ = true;
  return Status::Ok();
}

SupervisedWork HoldDuring(RigSupervisor* supervisor, double min_hold_s, double max_hold_s,
                          const std::function<Status(const std::atomic<bool>& abort)>& work) {
  FACEDYN_CHECK(max_hold_s > 0.0, "HoldDuring needs a bound on the hold");
  SupervisedWork result;
  std::atomic<bool> abort{false};
  std::atomic<bool> done{false};
  Status work_status;
  supervisor->NotifyOnStop(&abort);
  std::thread worker([&] {
    work_status = work(abort);
    done.store(true);
  });
  bool timed_out = false;
  StatusOr<HoldSummary> hold = supervisor->HoldWhile([&](double held_s) {
    if (done.load()) return work_status.ok() && held_s < min_hold_s;
    if (held_s >= max_hold_s) {
      timed_out = true;
      return false;
    }
    return true;
  });
  result.hold_status = hold.status();
  if (hold.ok()) result.hold = *hold;
  if (hold.ok() && timed_out) {
    // Stop the platform first: nothing ticks the supervisor while the work winds down.
    result.hold_status = FailedPreconditionError(
        fmt::format("rig {}: the work beside the hold did not end within {} s",
                    supervisor->config().name, max_hold_s));
    abort.store(true);
    const Status stopped = supervisor->RampToStop(result.hold_status.message());
    if (!stopped.ok()) result.hold_status = result.hold_status.WithContext(stopped.message());
  }
  if (!result.hold_status.ok()) {
    abort.store(true);
    // The platform is stopped (or its link lost) but the work may take a moment to wind down
    // (a take drains its cameras): keep reading the drive meanwhile, so that its comm watchdog
    // does not trip a drive that is standing still.
    const auto period = std::chrono::duration<double>(supervisor->config().safety.control_period_s);
    auto next = Clock::now();
    while (!done.load()) {
      if (Clock::now() >= next && supervisor->state() != RigState::kLinkLost) {
        (void)supervisor->ReadOnce();
        next = Clock::now() + std::chrono::duration_cast<Clock::duration>(period);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  worker.join();
  supervisor->NotifyOnStop(nullptr);
  result.aborted = abort.load();
  result.work_status = work_status;
  return result;
}

}  // namespace facedyn::rig
