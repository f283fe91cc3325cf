// RigSupervisor: the one object that moves the platform. It owns the drive link (transport +
// DriveClient) of a RigConfig and runs the control loop — heartbeat, measurement, ramp, trim,
// settle detection, exposure — one period at a time, inside the calls that need the platform
// to move or hold (WaitSettled, Hold, HoldWhile, RampToStop). There is no background thread:
// when the caller stops calling, the heartbeat stops, and the drive-side comm watchdog (armed
// by Arm() where the profile can set it over Modbus) stops the motor. That is the intended
// fail-safe for a crashed or killed facedyn.
//
// Threads: every method except Snapshot() is called from one thread, the supervisor's, and
// only that thread talks to the drive. Work that takes time while the platform moves (a take
// being recorded) runs on a thread of its own through HoldDuring(), while the supervisor's
// thread keeps ticking at safety.control_period_s; that work sees the platform through
// Snapshot() (a copy under a mutex) and is told to stop through an atomic flag. The
// alternative — the capture loop ticking the supervisor at its rate — would leave every gap
// in that loop unsupervised (ground truth being written, arming, draining, a camera that
// blocks), and a second thread calling into the supervisor would need every member locked
// and two threads on one Modbus link; one owner thread is simpler and easier to make right.
//
// Safety rules enforced here (software is an additional layer, never the only one):
//  - requests outside limits.min_hz..max_hz or above absolute_max_hz are refused before
//    anything is written; the drive setpoint never exceeds limits.motor_max_hz (DriveClient);
//  - the platform frequency changes at most limits.max_ramp_hz_per_s;
//  - a heartbeat that fails after the transport's retries is a lost link: the supervisor
//    tries to command a stop and reports the failure, naming the drive-side watchdog;
//  - a tripped drive is reported with its fault text and never reset except by ResetFault();
//  - a measured platform frequency above absolute_max_hz + overspeed_margin_hz stops it;
//  - a stop request (SIGINT/SIGTERM/SIGHUP/SIGQUIT set the flag passed in) or any error during
//    a move ramps the platform to a stop before the error is returned; a stop counts only when
//    the drive reports standstill, and the drive-side watchdog is disarmed only after that;
//  - every command, reply and state change goes to the SessionLog, and the person's cumulative
//    vibration exposure is accumulated (VibrationExposure).
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "core/json_io.h"
#include "core/status.h"
#include "rig/drive_client.h"
#include "rig/modbus_transport.h"
#include "rig/platform_model.h"
#include "rig/rig_config.h"
#include "rig/session_log.h"

namespace facedyn::rig {

enum class RigState {
  kIdle,
  kRamping,
  kSettling,
  kSettled,
  kStopping,
  kStopped,
  kFaulted,
  kLinkLost
};
const char* RigStateName(RigState state);

// One control period's view of the platform.
struct PlatformReading {
  double time_s = 0.0;  // since the supervisor connected
  bool running = false;
  bool faulted = false;
  int fault_code = 0;
  std::string fault_text;
  double output_hz = 0.0;      // drive output (motor electrical Hz)
  double measured_hz = 0.0;    // platform oscillation Hz (sensor, or estimated from output)
  double target_hz = 0.0;      // requested platform Hz (0 when stopping)
  double commanded_hz = 0.0;   // ramp-limited platform Hz being commanded
  double correction_hz = 0.0;  // trim
  double motor_setpoint_hz = 0.0;
  bool settled = false;

  Json ToJson() const;
};

// What another thread may know of the platform (RigSupervisor::Snapshot).
struct PlatformSnapshot {
  PlatformReading reading;  // the last control period's reading
  RigState state = RigState::kIdle;
};

struct HoldSummary {
  double seconds = 0.0;
  int samples = 0;
  double target_hz = 0.0;
  double mean_measured_hz = 0.0;
  double max_abs_error_hz = 0.0;  // over every measurement of the hold
  double rms_error_hz = 0.0;

  Json ToJson() const;
};

class RigSupervisor {
 public:
  // Opens the transport and the drive client. `log` may be null (no journal) and, like
  // `stop_requested` (may be null), must outlive the supervisor.
  static StatusOr<std::unique_ptr<RigSupervisor>> Connect(const RigConfig& config, SessionLog* log,
                                                          const std::atomic<bool>* stop_requested);
  // Ramps to stop if the platform may be moving, then disarms the watchdog (Close()).
  ~RigSupervisor();
  RigSupervisor(const RigSupervisor&) = delete;
  RigSupervisor& operator=(const RigSupervisor&) = delete;

  // Reads the drive and refuses to go on when it is tripped (the message names the fault and
  // `facedyn rig reset`); writes safety.comm_watchdog_s to the drive where the profile allows.
  Status Arm();
  // Checks `hz` against the limits (InvalidArgument naming the limit), then starts the drive
  // if needed and sets the ramp toward it. Call WaitSettled/Hold to make it happen.
  Status SetTargetHz(double hz);
  // Runs the control loop until the platform holds the target within platform.settle
  // (tolerance for settle.time_s). Ramps to stop and fails on timeout or any error.
  Status WaitSettled(double timeout_s);
  // Runs the control loop for `seconds`, measuring how well the target is held.
  StatusOr<HoldSummary> Hold(double seconds);
  // Runs the control loop while keep_holding(seconds held so far) is true (asked once per
  // control period). Any error ramps to stop and ends the hold.
  StatusOr<HoldSummary> HoldWhile(const std::function<bool(double held_s)>& keep_holding);
  // Commands a stop (the drive decelerates on its own ramp) and waits until the output is 0.
  // A refused or unconfirmed stop is sent again (3 attempts, each waiting up to
  // safety.stop_timeout_s); if standstill is never confirmed the error says so and names the
  // drive-side watchdog, which stays armed.
  Status RampToStop(const std::string& reason);
  // Explicit fault acknowledgement: the only place a trip is cleared.
  Status ResetFault();
  // One status read without any control action (for `rig status`).
  StatusOr<PlatformReading> ReadOnce();
  // Stops if needed and disarms the drive-side watchdog, but only after the drive confirmed
  // standstill; otherwise the watchdog stays armed and the error says so. Idempotent.
  Status Close();
  // Leaves the drive running at the current setpoint and disarms the drive-side watchdog, so
  // the drive keeps going after facedyn exits (`rig set --detach`).
  Status Detach();

  // Thread-safe: the last reading and state, for telemetry from another thread.
  PlatformSnapshot Snapshot() const;
  // Thread-safe to read: `flag` (may be null to detach) is set to true the moment the
  // supervisor starts to stop the platform or finds it stopped, faulted or its link lost, so
  // that work running beside a hold (HoldDuring) ends at once rather than after standstill.
  void NotifyOnStop(std::atomic<bool>* flag) { notify_on_stop_ = flag; }

  RigState state() const { return state_; }
  const PlatformReading& last() const { return last_; }
  VibrationExposure& exposure() { return exposure_; }
  const RigConfig& config() const { return config_; }
  ModbusTransport& transport() { return *transport_; }
  double ElapsedS() const;

 private:
  RigSupervisor(const RigConfig& config, SessionLog* log, const std::atomic<bool>* stop_requested);
  Status Tick();
  // Adds the time since the last exposure update at `platform_hz`, with no clamp: the platform
  // vibrated for all of it, however late this tick is.
  void AccountExposure(double platform_hz);
  // Copies last_ and state_ for Snapshot().
  void Publish();
  Status ReadPlatform(PlatformReading* reading);
  Status WriteMotorSetpoint(double motor_hz);
  Status WriteWatchdog(double seconds);
  Status FailAndStop(const Status& error);
  void SetState(RigState state, const std::string& reason);
  void LogCommand(const std::string& what, Json fields, const Status& result);
  bool StopRequested() const { return stop_requested_ != nullptr && stop_requested_->load(); }
  Status LinkLost(const Status& error);
  // What stops the motor when facedyn cannot: names the armed watchdog, or says to stop by hand.
  std::string WatchdogFallback() const;

  RigConfig config_;
  SessionLog* log_;
  const std::atomic<bool>* stop_requested_;
  std::unique_ptr<ModbusTransport> transport_;
  std::unique_ptr<DriveClient> client_;
  PlatformModel model_;
  FrequencyTrim trim_;
  SettleDetector settle_;
  VibrationExposure exposure_;

  RigState state_ = RigState::kIdle;
  PlatformReading last_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_tick_;      // the ramp's clock
  std::chrono::steady_clock::time_point last_exposure_;  // exposure counted up to here
  std::atomic<bool>* notify_on_stop_ = nullptr;
  mutable std::mutex snapshot_mutex_;
  PlatformSnapshot snapshot_;
  double target_hz_ = 0.0;
  double commanded_hz_ = 0.0;
  double written_motor_hz_ = -1.0;  // last setpoint written (-1: none)
  double at_speed_since_s_ = -1.0;
  bool jumped_for_target_ = false;
  double run_commanded_at_s_ = -1.0;  // < 0: no run command outstanding
  TransportStats logged_stats_;
  bool watchdog_armed_ = false;
  bool standstill_confirmed_ = false;  // the drive last reported 0 Hz output and not running
  bool closed_ = false;
};

// Runs `work` on a thread of its own while the calling thread — the supervisor's — keeps the
// control loop running (HoldWhile): the hold lasts until `work` returns, and at least
// min_hold_s when it succeeds. `abort` becomes true as soon as the supervisor stops the
// platform (a trip, overspeed, a disagreeing sensor, a stop request, a lost link) or the hold
// reaches max_hold_s (> 0; a work that never returns must not keep a person vibrating); work
// must then return promptly. Returns after `work` has returned. The hold's error, when there
// is one, comes first: the platform is then stopped (RampToStop) or its link lost.
struct SupervisedWork {
  Status hold_status;  // the supervisor's verdict
  HoldSummary hold;
  Status work_status;    // what `work` returned
  bool aborted = false;  // `work` was told to stop
};
SupervisedWork HoldDuring(RigSupervisor* supervisor, double min_hold_s, double max_hold_s,
                          const std::function<Status(const std::atomic<bool>& abort)>& work);

}  // namespace facedyn::rig
