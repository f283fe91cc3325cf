// A simulated variable-frequency drive and vibrating platform behind a real libmodbus server.
//
// Two parts, so the physics can be tested on a virtual clock and the protocol on a real one:
//
// - DriveModel: the drive's state machine, motor and platform, advanced by explicit time steps.
//   The output frequency ramps toward the setpoint (or toward 0 when stopped) at
//   accel_hz_per_s; a trip removes the output at once, as a real drive coasts on a trip; the
//   comm watchdog stops the motor (and latches watchdog_fault_code, if non-zero) when no valid
//   request arrived for watchdog_s seconds while running. The platform (an eccentric mass on
//   an induction motor) oscillates at
//
//       platform_hz = output_hz * platform_ratio * (1 - s),
//       s = slip_base + slip_load * (output_hz / slip_reference_hz)^2
//
//   i.e. the rotor lags the drive's electrical frequency by a slip that grows with the load the
//   mass puts on it. The oscillation sensor integrates the platform's phase and reports the
//   mean frequency over the last sensor_window_s (what counting accelerometer zero crossings
//   over a window gives) plus Gaussian noise of sensor_noise_hz. The slip the controller
//   assumes (RIG.yaml platform.slip) is a single number, so open loop it misses the true
//   platform frequency by up to a few tenths of a hertz; the closed-loop trim has to fix that.
// - DriveSim: a server thread that owns a libmodbus context — TCP on host:port (port 0 picks
//   a free port) serving any number of clients, or RTU on a serial device (e.g. one end of a
//   socat pty pair) — answering with modbus_receive/modbus_reply over a modbus_mapping_t laid
//   out by a DriveProfile, stepping the model on steady_clock (at most 50 ms per server loop, so
//   a starved server thread slows the model instead of tripping its watchdog). Writes to the
//   profile's command register are interpreted as run/stop/fault-reset; the setpoint register is
//   scaled to Hz; status, output frequency, oscillation frequency and fault code are refreshed
//   before every reply. Fault injection: drop the next N requests unanswered, delay replies, garble
//   the next N replies (random bytes: CRC errors on RTU, a bad header on TCP), answer the next N
//   requests with a Modbus exception, cut the link (requests vanish, as on a cut cable), and
//   trip on command or after a given running time.
#pragma once

#include <modbus.h>

#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/config_node.h"
#include "core/status.h"
#include "rig/drive_profile.h"

namespace facedyn::sim {

struct DriveModelOptions {
  double accel_hz_per_s = 5.0;  // ramp rate up and down
  double max_hz = 50.0;         // setpoints above are clamped, like a drive's Pr. max frequency
  double watchdog_s = 0.0;      // 0 = off
  int watchdog_fault_code = 0;  // latched when the watchdog fires (0 = stop without a trip)

  // Platform (see the header comment).
  double platform_ratio = 1.0;  // platform cycles per electrical cycle at zero slip
  double slip_base = 0.015;
  double slip_load = 0.03;
  double slip_reference_hz = 11.0;
  double sensor_window_s = 0.5;
  double sensor_noise_hz = 0.004;  // standard deviation of one sensor reading
  // A miscalibrated sensor (fault injection): it reports sensor_gain times the true mean.
  double sensor_gain = 1.0;
  uint64_t seed = 1;

  Status Check() const;
};

// Reads a RIG.yaml `sim:` section (the simulated drive's and platform's physics; see
// config/rigs/sim-tcp.yaml) into *options; unknown fields and out-of-range values are errors
// naming the field.
Status ParseDriveModelOptions(const ConfigNode& node, DriveModelOptions* options);

struct DriveSimOptions;

// The simulated drive a RIG.yaml describes: its drive profile, its endpoint (TCP host:port, or
// the RTU device and line settings) and its `sim:` physics.
Status LoadDriveSimFromRig(const std::string& rig_path, rig::DriveProfile* profile,
                           DriveSimOptions* options);

struct DriveModelState {
  bool run_commanded = false;
  double setpoint_hz = 0.0;
  double output_hz = 0.0;
  int fault_code = 0;
  bool watchdog_fired = false;
  double platform_hz = 0.0;  // true oscillation frequency (ground truth)
  double sensor_hz = 0.0;    // what the oscillation sensor reports
  double time_s = 0.0;       // model time
};

class DriveModel {
 public:
  explicit DriveModel(const DriveModelOptions& options);

  void SetSetpointHz(double hz);
  void Run();
  void Stop();
  void ResetFault();
  void ForceFault(int code);
  // Trips with `code` once the motor has been running for `after_s` more seconds.
  void ScheduleTrip(double after_s, int code);
  // A valid request arrived (feeds the comm watchdog).
  void NoteRequest() { silent_s_ = 0.0; }
  // The drive-side watchdog time as written over Modbus (0 = off).
  void SetWatchdogS(double watchdog_s) { options_.watchdog_s = watchdog_s; }
  // Fault injection: the sensor starts reporting `gain` times the truth (a sensor gone bad).
  void SetSensorGain(double gain) { options_.sensor_gain = gain; }
  // Advances the motor, platform, sensor and watchdog by dt_s seconds.
  void Advance(double dt_s);

  // Slip at a given output frequency (see the header comment).
  double SlipAt(double output_hz) const;

  const DriveModelState& state() const { return state_; }
  const DriveModelOptions& options() const { return options_; }
  bool running() const { return state_.run_commanded && state_.fault_code == 0; }
  // What the status word's "running" bit reports: the output is live, which on a real drive
  // includes the deceleration ramp after a stop command until the output reaches 0 Hz. (A stop
  // that cleared the bit at once would let the output register, which rounds to its 0.01 Hz
  // count, read 0 while the motor still turns at a few mHz.)
  bool output_active() const {
    return state_.fault_code == 0 && (state_.run_commanded || state_.output_hz > 0.0);
  }

 private:
  DriveModelOptions options_;
  DriveModelState state_;
  double silent_s_ = 0.0;
  double phase_cycles_ = 0.0;
  std::deque<std::pair<double, double>> phase_history_;  // (time_s, phase_cycles)
  double trip_after_s_ = -1.0;                           // < 0: none scheduled
  int trip_code_ = 0;
  std::mt19937_64 random_;
  std::normal_distribution<double> noise_{0.0, 1.0};
};

// One register write the simulated drive acts on, decoded from a request.
struct DriveWrite {
  int function = 0;  // MODBUS_FC_WRITE_SINGLE_REGISTER (06) or _MULTIPLE_REGISTERS (16)
  int address = 0;   // first register, PDU address
  std::vector<uint16_t> values;
};

// The request handling of DriveSim as pure functions (no socket, no libmodbus context), so the
// part that interprets outside bytes can be tested and fuzzed on its own.
//
// DecodeAcceptedWrite reads a request PDU (function code first; no MBAP header, unit id or
// CRC) of `length` bytes and returns the write a drive accepts: FC06 to an address below
// register_count, or FC16 of 1..123 registers (Modbus Application Protocol v1.1b3, 6.12) with
// byte count 2 x quantity, every value present and every register below register_count.
// Anything else (reads, other functions, malformed or out-of-range requests) is nullopt: the
// drive answers it (an exception, or the read values) and acts on none of it.
std::optional<DriveWrite> DecodeAcceptedWrite(const uint8_t* pdu, int length, int register_count);
// What an accepted write does: run, stop or fault reset through the command and reset
// registers, a new setpoint, the comm-watchdog time.
void ApplyDriveWrite(const rig::DriveProfile& profile, const DriveWrite& write, DriveModel* model);
// The registers the drive shows, from the model: status word, output frequency, oscillation
// frequency and fault code, into registers[0, register_count) (the profile's registers that lie
// beyond are left out).
void RefreshDriveRegisters(const rig::DriveProfile& profile, const DriveModel& model,
                           uint16_t* registers, int register_count);

struct DriveSimOptions {
  // TCP endpoint, used when rtu_device is empty.
  std::string host = "127.0.0.1";
  int port = 0;  // 0: any free port (see DriveSim::port())
  // RTU: the serial device to serve on (e.g. a socat pty), and its line settings.
  std::string rtu_device;
  int baud = 19200;
  char parity = 'N';
  int data_bits = 8;
  int stop_bits = 1;

  DriveModelOptions model;
  double step_s = 0.005;  // server loop period when idle

  Status Check() const;
  bool is_rtu() const { return !rtu_device.empty(); }
};

class DriveSim {
 public:
  // Binds (TCP) or opens the device (RTU) and starts the server thread; errors name the
  // address or device.
  static StatusOr<std::unique_ptr<DriveSim>> Start(const rig::DriveProfile& profile,
                                                   const DriveSimOptions& options);
  ~DriveSim();  // stops the thread and closes every socket
  DriveSim(const DriveSim&) = delete;
  DriveSim& operator=(const DriveSim&) = delete;

  int port() const { return port_; }
  const std::string& host() const { return options_.host; }
  // "tcp 127.0.0.1:5020" or "rtu /dev/pts/3".
  std::string Describe() const;

  // Fault injection, callable from any thread.
  void DropNextRequests(int count) { drop_requests_ = count; }
  void SetReplyDelayS(double delay_s) { reply_delay_s_ = delay_s; }
  void GarbleNextReplies(int count) { garble_replies_ = count; }
  // Answers the next `count` requests with exception `code` (MODBUS_EXCEPTION_*).
  void ExceptionNextReplies(int count, int code);
  // While cut, requests are read and discarded: neither applied nor answered nor counted by
  // the drive's watchdog, as when the cable is pulled.
  void CutLink(bool cut) { link_cut_ = cut; }
  void ForceFault(int code);
  void ScheduleTrip(double after_s, int code);
  // The oscillation sensor reports `gain` times the true platform frequency from now on.
  void SetSensorGain(double gain);

  DriveModelState state() const;
  long requests_served() const { return requests_served_; }
  long requests_dropped() const { return requests_dropped_; }
  long replies_garbled() const { return replies_garbled_; }

 private:
  DriveSim(const rig::DriveProfile& profile, const DriveSimOptions& options);
  Status Listen();
  Status OpenSerial();
  void Serve();
  void ServeRtu();
  // Handles one received frame on the current socket; false when the reply could not be sent.
  bool Answer(const uint8_t* query, int length);
  void RefreshRegisters();
  void AdvanceModel();

  rig::DriveProfile profile_;
  DriveSimOptions options_;
  int port_ = 0;
  modbus_t* ctx_ = nullptr;              // server thread only after Start()
  modbus_mapping_t* mapping_ = nullptr;  // server thread only after Start()
  int listen_socket_ = -1;
  int header_length_ = 0;
  std::chrono::steady_clock::time_point last_advance_;

  mutable std::mutex model_mutex_;
  DriveModel model_;

  std::atomic<int> drop_requests_{0};
  std::atomic<double> reply_delay_s_{0.0};
  std::atomic<int> garble_replies_{0};
  std::atomic<int> exception_replies_{0};
  std::atomic<int> exception_code_{MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY};
  std::atomic<bool> link_cut_{false};
  std::atomic<long> requests_served_{0};
  std::atomic<long> requests_dropped_{0};
  std::atomic<long> replies_garbled_{0};
  std::atomic<bool> stopping_{false};
  std::mt19937 garble_random_{12345};
  std::thread thread_;
};

}  // namespace facedyn::sim
