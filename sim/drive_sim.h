// A simulated variable-frequency drive behind a real libmodbus TCP server.
//
// Two parts, so the physics can be tested on a virtual clock and the protocol on a real one:
//
// - DriveModel: the drive's state machine and motor, advanced by explicit time steps. The
//   output frequency ramps toward the setpoint (or toward 0 when stopped) at accel_hz_per_s;
//   a forced trip stops the output at once, as a real drive coasts on a trip; the comm
//   watchdog stops the motor (and latches watchdog_fault_code, if non-zero) when no valid
//   request arrived for watchdog_s seconds while running.
// - DriveSim: a server thread that owns a libmodbus TCP context, listens on 127.0.0.1 (port 0
//   picks a free port), serves any number of clients with modbus_receive/modbus_reply over a
//   modbus_mapping_t laid out by a DriveProfile, and steps the model on steady_clock. Writes
//   to the profile's command register are interpreted as run/stop/fault-reset; the setpoint
//   register is scaled to Hz; status, output frequency and fault code are refreshed before
//   every reply. Fault injection: drop the next N requests unanswered, delay replies, force a
//   fault code.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <modbus.h>

#include "core/status.h"
#include "rig/drive_profile.h"

namespace facedyn::sim {

struct DriveModelOptions {
  double accel_hz_per_s = 5.0;   // ramp rate up and down
  double max_hz = 50.0;          // setpoints above are clamped, like a drive's Pr. max frequency
  double watchdog_s = 0.0;       // 0 = off
  int watchdog_fault_code = 0;   // latched when the watchdog fires (0 = stop without a trip)

  Status Check() const;
};

struct DriveModelState {
  bool run_commanded = false;
  double setpoint_hz = 0.0;
  double output_hz = 0.0;
  int fault_code = 0;
  bool watchdog_fired = false;
};

class DriveModel {
 public:
  explicit DriveModel(const DriveModelOptions& options) : options_(options) {}

  void SetSetpointHz(double hz);
  void Run();
  void Stop();
  void ResetFault();
  void ForceFault(int code);
  // A valid request arrived (feeds the comm watchdog).
  void NoteRequest() { silent_s_ = 0.0; }
  // The drive-side watchdog time as written over Modbus (0 = off).
  void SetWatchdogS(double watchdog_s) { options_.watchdog_s = watchdog_s; }
  // Advances the motor and the watchdog by dt_s seconds.
  void Advance(double dt_s);

  const DriveModelState& state() const { return state_; }
  bool running() const { return state_.run_commanded && state_.fault_code == 0; }

 private:
  DriveModelOptions options_;
  DriveModelState state_;
  double silent_s_ = 0.0;
};

struct DriveSimOptions {
  std::string host = "127.0.0.1";
  int port = 0;  // 0: any free port (see DriveSim::port())
  DriveModelOptions model;
  double step_s = 0.005;  // server loop period when idle

  Status Check() const;
};

class DriveSim {
 public:
  // Binds and starts the server thread; errors name the address.
  static StatusOr<std::unique_ptr<DriveSim>> Start(const rig::DriveProfile& profile,
                                                    const DriveSimOptions& options);
  ~DriveSim();  // stops the thread and closes every socket
  DriveSim(const DriveSim&) = delete;
  DriveSim& operator=(const DriveSim&) = delete;

  int port() const { return port_; }
  const std::string& host() const { return options_.host; }

  // Fault injection, callable from any thread.
  void DropNextRequests(int count) { drop_requests_ = count; }
  void SetReplyDelayS(double delay_s) { reply_delay_s_ = delay_s; }
  void ForceFault(int code);

  DriveModelState state() const;
  long requests_served() const { return requests_served_; }
  long requests_dropped() const { return requests_dropped_; }

 private:
  DriveSim(const rig::DriveProfile& profile, const DriveSimOptions& options);
  Status Listen();
  void Serve();
  void HandleWrite(int function, int address, int count);
  void RefreshRegisters();

  rig::DriveProfile profile_;
  DriveSimOptions options_;
  int port_ = 0;
  modbus_t* ctx_ = nullptr;             // server thread only after Start()
  modbus_mapping_t* mapping_ = nullptr;  // server thread only after Start()
  int listen_socket_ = -1;

  mutable std::mutex model_mutex_;
  DriveModel model_;

  std::atomic<int> drop_requests_{0};
  std::atomic<double> reply_delay_s_{0.0};
  std::atomic<long> requests_served_{0};
  std::atomic<long> requests_dropped_{0};
  std::atomic<bool> stopping_{false};
  std::thread thread_;
};

}  // namespace facedyn::sim
