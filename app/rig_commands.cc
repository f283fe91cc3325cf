// `facedyn rig serve-sim|set|stop|status|reset`: the platform drive from the command line.
//
// With --config RIG.yaml every command goes through the RigSupervisor (limits, ramp, trim,
// heartbeat, drive-side watchdog, session log); --profile P --tcp HOST:PORT talks to the drive
// directly with only DriveClient's setpoint window, for bring-up and register checks.

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>

#include "app/command.h"
#include "app/rig_demo.h"
#include "core/config_node.h"
#include "core/json_io.h"
#include "rig/drive_client.h"
#include "rig/drive_profile.h"
#include "rig/modbus_transport.h"
#include "rig/rig_config.h"
#include "rig/session_log.h"
#include "rig/stop_signal.h"
#include "rig/supervisor.h"
#include "rig/usb_controller.h"
#include "sim/drive_sim.h"

namespace facedyn::app {
namespace {

struct RigOptions {
  std::string config;
  std::string profile;
  std::string tcp;
  std::string log;
  double hz = 0.0;
  bool json = false;
  double timeout_s = 0.5;
  int retries = 2;
  double seconds = 0.0;
  double settle_timeout_s = 60.0;
  bool detach = false;
};

struct Connection {
  rig::DriveProfile profile;
  std::unique_ptr<rig::ModbusTransport> transport;
  std::unique_ptr<rig::DriveClient> client;
};

StatusOr<Connection> Connect(const RigOptions& options) {
  Connection c;
  FACEDYN_ASSIGN_OR_RETURN(c.profile, rig::LoadDriveProfile(options.profile));
  rig::TransportOptions transport;
  FACEDYN_RETURN_IF_ERROR(rig::ParseTcpEndpoint(options.tcp, &transport));
  transport.unit_id = c.profile.unit_id;
  transport.response_timeout_s = options.timeout_s;
  transport.retries = options.retries;
  FACEDYN_ASSIGN_OR_RETURN(c.transport, rig::ModbusTransport::Open(transport));
  c.client = std::make_unique<rig::DriveClient>(c.transport.get(), c.profile);
  return c;
}

Status PrintStatus(rig::DriveClient& client, bool json) {
  FACEDYN_ASSIGN_OR_RETURN(const rig::DriveStatus status, client.ReadStatus());
  if (json) {
    Json out = status.ToJson();
    out["profile"] = client.profile().name;
    std::printf("%s\n", out.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
  } else {
    std::printf("drive     %s\nrunning   %s\noutput    %.2f Hz\nfault     %s\n",
                client.profile().name.c_str(), status.running ? "yes" : "no", status.output_hz,
                status.faulted ? status.fault_text.c_str() : "none");
  }
  return Status::Ok();
}

// The supervised path: config, optional log, supervisor.
struct Supervised {
  rig::RigConfig config;
  std::unique_ptr<rig::SessionLog> log;
  std::unique_ptr<rig::RigSupervisor> supervisor;
};

// "1209" or "0x1209" -> 0x1209; `flag` names the option in errors.
StatusOr<uint16_t> ParseUsbId(const std::string& text, const std::string& flag) {
  char* end = nullptr;
  const long value = std::strtol(text.c_str(), &end, 16);
  if (text.empty() || *end != '\0' || value < 0 || value > 0xFFFF) {
    return InvalidArgumentError(
        fmt::format("{}: '{}' is not a 16-bit hex id (e.g. 1209)", flag, text));
  }
  return static_cast<uint16_t>(value);
}

StatusOr<Supervised> ConnectSupervised(const RigOptions& options, const std::atomic<bool>* stop) {
  Supervised s;
  FACEDYN_ASSIGN_OR_RETURN(s.config, rig::LoadRigConfig(options.config));
  if (!options.log.empty()) {
    FACEDYN_ASSIGN_OR_RETURN(s.log, rig::SessionLog::Open(options.log));
  }
  FACEDYN_ASSIGN_OR_RETURN(s.supervisor, rig::RigSupervisor::Connect(s.config, s.log.get(), stop));
  return s;
}

Json ReadingJson(const rig::RigSupervisor& supervisor, const rig::PlatformReading& reading) {
  Json out = reading.ToJson();
  out["rig"] = supervisor.config().name;
  out["profile"] = supervisor.config().profile.name;
  out["state"] = rig::RigStateName(supervisor.state());
  return out;
}

void PrintReading(const rig::RigSupervisor& supervisor, const rig::PlatformReading& r, bool json) {
  if (json) {
    std::printf("%s\n",
                ReadingJson(supervisor, r).dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
    return;
  }
  std::printf(
      "rig       %s (drive %s)\nstate     %s\nrunning   %s\noutput    %.2f Hz (drive)\n"
      "platform  %.3f Hz (%s)\nfault     %s\n",
      supervisor.config().name.c_str(), supervisor.config().profile.name.c_str(),
      rig::RigStateName(supervisor.state()), r.running ? "yes" : "no", r.output_hz, r.measured_hz,
      supervisor.config().feedback == "sensor" ? "measured" : "estimated from the drive output",
      r.faulted ? r.fault_text.c_str() : "none");
}

void AddConnectionOptions(CLI::App* command, RigOptions* options) {
  auto* config =
      command->add_option("--config", options->config, "Rig config YAML (config/rigs/*.yaml)");
  command
      ->add_option("--profile", options->profile, "Drive profile YAML, direct mode (needs --tcp)")
      ->excludes(config);
  command->add_option("--tcp", options->tcp, "Drive (or gateway) address HOST:PORT, direct mode")
      ->excludes(config);
  command->add_option("--timeout", options->timeout_s, "Direct mode: response timeout in seconds")
      ->capture_default_str();
  command->add_option("--retries", options->retries, "Direct mode: extra attempts per request")
      ->capture_default_str();
  command
      ->add_option("--log", options->log, "Append the JSON Lines session log here (with --config)")
      ->needs(config);
}

void RequireConnection(const RigOptions& options) {
  if (options.config.empty() && (options.profile.empty() || options.tcp.empty())) {
    throw CLI::RequiredError("--config RIG.yaml (or --profile P with --tcp HOST:PORT)");
  }
}

}  // namespace

void AddRigCommands(CLI::App& app, CommandRunner* selected) {
  auto* rig_command = app.add_subcommand("rig", "The vibrating platform's drive over Modbus");
  rig_command->require_subcommand(1);

  struct ServeOptions {
    std::string config;
    std::string profile;
    std::string tcp;
    std::string rtu;
    double seconds = 0.0;
    double trip_after_s = 0.0;
    int trip_code = 1;
    sim::DriveSimOptions sim;
  };
  auto serve = std::make_shared<ServeOptions>();
  auto* serve_command = rig_command->add_subcommand(
      "serve-sim", "Run a simulated drive and platform behind a real Modbus server (TCP or RTU)");
  auto* serve_config = serve_command->add_option(
      "--config", serve->config,
      "Rig config YAML: serve its profile at its endpoint with its sim: section");
  serve_command
      ->add_option("--profile", serve->profile,
                   "Drive profile YAML whose map to serve (default: config/drives/sim.yaml)")
      ->excludes(serve_config);
  auto* serve_tcp = serve_command->add_option("--tcp", serve->tcp,
                                              "Listen address HOST:PORT (port 0: any free port)");
  serve_command
      ->add_option("--rtu", serve->rtu, "Serve Modbus RTU on this serial device (e.g. a socat pty)")
      ->excludes(serve_tcp);
  serve_command->add_option("--seconds", serve->seconds, "Stop after this long (0: until Ctrl-C)")
      ->capture_default_str();
  serve_command->add_option("--accel-hz-per-s", serve->sim.model.accel_hz_per_s, "Motor ramp rate")
      ->capture_default_str();
  serve_command
      ->add_option("--watchdog-s", serve->sim.model.watchdog_s,
                   "Comm watchdog until a client writes its own: stop when no request for this "
                   "long (0: off)")
      ->capture_default_str();
  serve_command
      ->add_option("--watchdog-fault-code", serve->sim.model.watchdog_fault_code,
                   "Fault code latched when the comm watchdog fires (0: stop without a trip)")
      ->capture_default_str();
  serve_command
      ->add_option("--trip-after-s", serve->trip_after_s,
                   "Fault injection: trip once the motor has run this long (0: never)")
      ->capture_default_str();
  serve_command->add_option("--trip-code", serve->trip_code, "Fault code of the injected trip")
      ->capture_default_str();
  serve_command->callback([serve, selected] {
    *selected = [serve]() -> Status {
      rig::DriveProfile profile;
      sim::DriveSimOptions options = serve->sim;
      if (serve->config.empty() && serve->profile.empty()) {
        // Default: the simulated drive's own map from the shipped config folder.
        FACEDYN_ASSIGN_OR_RETURN(const std::string config_dir, FindConfigDir());
        serve->profile = config_dir + "/drives/sim.yaml";
      }
      if (!serve->config.empty()) {
        FACEDYN_RETURN_IF_ERROR(sim::LoadDriveSimFromRig(serve->config, &profile, &options));
      } else {
        FACEDYN_ASSIGN_OR_RETURN(profile, rig::LoadDriveProfile(serve->profile));
        if (serve->tcp.empty() && serve->rtu.empty()) serve->tcp = "127.0.0.1:5020";
      }
      if (!serve->tcp.empty()) {
        rig::TransportOptions endpoint;
        FACEDYN_RETURN_IF_ERROR(rig::ParseTcpEndpoint(serve->tcp, &endpoint));
        options.rtu_device.clear();
        options.host = endpoint.host;
        options.port = endpoint.port;
      }
      if (!serve->rtu.empty()) options.rtu_device = serve->rtu;
      FACEDYN_ASSIGN_OR_RETURN(auto server, sim::DriveSim::Start(profile, options));
      if (serve->trip_after_s > 0.0) server->ScheduleTrip(serve->trip_after_s, serve->trip_code);
      // The address goes to stdout so scripts can start us with port 0 and read where we are.
      if (options.is_rtu()) {
        std::printf("listening rtu %s profile %s\n", options.rtu_device.c_str(),
                    profile.name.c_str());
      } else {
        std::printf("listening %s:%d profile %s\n", server->host().c_str(), server->port(),
                    profile.name.c_str());
      }
      std::fflush(stdout);
      const std::atomic<bool>* stop = rig::InstallStopSignalHandlers();
      const auto start = std::chrono::steady_clock::now();
      while (!stop->load()) {
        if (serve->seconds > 0.0 &&
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >=
                serve->seconds) {
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
      spdlog::info("simulated drive served {} requests", server->requests_served());
      return Status::Ok();
    };
  });

  struct UsbOptions {
    std::string vid = "1209";
    std::string pid = "0001";
    std::string serial;
    bool json = false;
  };
  auto usb = std::make_shared<UsbOptions>();
  auto* usb_command = rig_command->add_subcommand(
      "usb-status",
      "Find the USB platform/sync controller (rig/usb_controller.h) and print its info and status");
  usb_command->add_option("--vid", usb->vid, "Vendor id, hex")->capture_default_str();
  usb_command->add_option("--pid", usb->pid, "Product id, hex")->capture_default_str();
  usb_command->add_option("--serial", usb->serial,
                          "Serial number string (default: the first match)");
  usb_command->add_flag("--json", usb->json, "Print JSON on stdout");
  usb_command->callback([usb, selected] {
    *selected = [usb]() -> Status {
      rig::UsbControllerOptions options;
      FACEDYN_ASSIGN_OR_RETURN(options.vendor_id, ParseUsbId(usb->vid, "--vid"));
      FACEDYN_ASSIGN_OR_RETURN(options.product_id, ParseUsbId(usb->pid, "--pid"));
      options.serial = usb->serial;
      FACEDYN_ASSIGN_OR_RETURN(auto controller, rig::UsbPlatformController::Open(options));
      FACEDYN_ASSIGN_OR_RETURN(const rig::UsbControllerStatus status, controller->ReadStatus());
      if (usb->json) {
        Json out;
        out["device"] = options.Describe();
        out["info"] = controller->info().ToJson();
        out["status"] = status.ToJson();
        std::printf("%s\n", out.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        std::printf(
            "controller %s, protocol %d, firmware %d\nrunning    %s\nsetpoint   %.2f Hz\n"
            "measured   %.2f Hz\nfault      %s\n",
            options.Describe().c_str(), controller->info().protocol_version,
            controller->info().firmware_version, status.running ? "yes" : "no", status.setpoint_hz,
            status.measured_hz,
            status.faulted ? std::to_string(status.fault_code).c_str() : "none");
      }
      return Status::Ok();
    };
  });

  auto set_options = std::make_shared<RigOptions>();
  auto* set_command = rig_command->add_subcommand(
      "set",
      "Run the platform at a frequency (6-11 Hz). With --config: ramp, trim until settled, "
      "hold until Ctrl-C or --seconds, then ramp to stop");
  AddConnectionOptions(set_command, set_options.get());
  set_command
      ->add_option("--hz", set_options->hz,
                   "Platform frequency in Hz (--config) or drive frequency (direct)")
      ->required();
  set_command->add_flag("--json", set_options->json, "Print the result as JSON");
  set_command
      ->add_option("--seconds", set_options->seconds,
                   "With --config: hold this long, then ramp to stop (0: until Ctrl-C)")
      ->capture_default_str();
  set_command
      ->add_option("--settle-timeout", set_options->settle_timeout_s,
                   "With --config: fail if not settled by then (s)")
      ->capture_default_str();
  set_command->add_flag(
      "--detach", set_options->detach,
      "With --config: exit once settled and leave the drive running (disarms the drive-side "
      "comm watchdog; stop it with `rig stop`)");
  set_command->callback([set_options, selected] {
    RequireConnection(*set_options);
    *selected = [set_options]() -> Status {
      const RigOptions& o = *set_options;
      if (o.config.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(Connection c, Connect(o));
        FACEDYN_RETURN_IF_ERROR(c.client->SetFrequencyHz(o.hz));
        FACEDYN_RETURN_IF_ERROR(c.client->Start());
        return PrintStatus(*c.client, o.json);
      }
      if (!(o.seconds >= 0.0))
        return InvalidArgumentError(fmt::format("--seconds: {} must be >= 0", o.seconds));
      const std::atomic<bool>* stop = rig::InstallStopSignalHandlers();
      FACEDYN_ASSIGN_OR_RETURN(Supervised s, ConnectSupervised(o, stop));
      rig::RigSupervisor& supervisor = *s.supervisor;
      FACEDYN_RETURN_IF_ERROR(supervisor.Arm());
      FACEDYN_RETURN_IF_ERROR(supervisor.SetTargetHz(o.hz));
      FACEDYN_RETURN_IF_ERROR(supervisor.WaitSettled(o.settle_timeout_s));
      const rig::PlatformReading settled = supervisor.last();
      Json out = ReadingJson(supervisor, settled);
      if (o.detach) {
        FACEDYN_RETURN_IF_ERROR(supervisor.Detach());
        spdlog::warn(
            "rig {}: left running at {} Hz with the drive-side comm watchdog disarmed; "
            "`facedyn rig stop --config {}` stops it",
            s.config.name, o.hz, o.config);
      } else {
        spdlog::info(
            "rig {}: settled at {:.3f} Hz (target {} Hz); holding{}", s.config.name,
            settled.measured_hz, o.hz,
            o.seconds > 0.0 ? fmt::format(" for {} s", o.seconds) : ", Ctrl-C ramps to stop");
        const double hold_s = o.seconds > 0.0 ? o.seconds : 1e9;
        auto hold = supervisor.Hold(hold_s);
        if (!hold.ok() && hold.status().code() != StatusCode::kAborted) return hold.status();
        if (hold.ok()) {
          out["hold"] = hold->ToJson();
          FACEDYN_RETURN_IF_ERROR(supervisor.RampToStop("hold done"));
        }
        out["state"] = rig::RigStateName(supervisor.state());
      }
      out["exposure"] = supervisor.exposure().ToJson();
      if (o.json) {
        std::printf("%s\n", out.dump(2, ' ', false, kJsonReplaceInvalidUtf8).c_str());
      } else {
        std::printf("settled at %.3f Hz (target %.2f Hz, trim %+.3f Hz)\n", settled.measured_hz,
                    o.hz, settled.correction_hz);
      }
      return Status::Ok();
    };
  });

  auto stop_options = std::make_shared<RigOptions>();
  auto* stop_command =
      rig_command->add_subcommand("stop", "Stop the drive (ramp to stop) and wait for standstill");
  AddConnectionOptions(stop_command, stop_options.get());
  stop_command->add_flag("--json", stop_options->json, "Print the resulting status as JSON");
  stop_command->callback([stop_options, selected] {
    RequireConnection(*stop_options);
    *selected = [stop_options]() -> Status {
      const RigOptions& o = *stop_options;
      if (o.config.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(Connection c, Connect(o));
        FACEDYN_RETURN_IF_ERROR(c.client->Stop());
        return PrintStatus(*c.client, o.json);
      }
      FACEDYN_ASSIGN_OR_RETURN(Supervised s,
                               ConnectSupervised(o, nullptr));  // a stop is not interruptible
      FACEDYN_RETURN_IF_ERROR(s.supervisor->RampToStop("rig stop"));
      PrintReading(*s.supervisor, s.supervisor->last(), o.json);
      return Status::Ok();
    };
  });

  auto status_options = std::make_shared<RigOptions>();
  auto* status_command =
      rig_command->add_subcommand("status", "Running, output and platform frequency, fault");
  AddConnectionOptions(status_command, status_options.get());
  status_command->add_flag("--json", status_options->json, "Print JSON on stdout");
  status_command->callback([status_options, selected] {
    RequireConnection(*status_options);
    *selected = [status_options]() -> Status {
      const RigOptions& o = *status_options;
      if (o.config.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(Connection c, Connect(o));
        return PrintStatus(*c.client, o.json);
      }
      FACEDYN_ASSIGN_OR_RETURN(Supervised s, ConnectSupervised(o, nullptr));
      FACEDYN_ASSIGN_OR_RETURN(const rig::PlatformReading reading, s.supervisor->ReadOnce());
      PrintReading(*s.supervisor, reading, o.json);
      return Status::Ok();
    };
  });

  auto reset_options = std::make_shared<RigOptions>();
  auto* reset_command =
      rig_command->add_subcommand("reset", "Acknowledge a drive trip (explicit only)");
  AddConnectionOptions(reset_command, reset_options.get());
  reset_command->add_flag("--json", reset_options->json, "Print the resulting status as JSON");
  reset_command->callback([reset_options, selected] {
    RequireConnection(*reset_options);
    *selected = [reset_options]() -> Status {
      const RigOptions& o = *reset_options;
      if (o.config.empty()) {
        FACEDYN_ASSIGN_OR_RETURN(Connection c, Connect(o));
        FACEDYN_RETURN_IF_ERROR(c.client->ResetFault());
        return PrintStatus(*c.client, o.json);
      }
      FACEDYN_ASSIGN_OR_RETURN(Supervised s, ConnectSupervised(o, nullptr));
      FACEDYN_RETURN_IF_ERROR(s.supervisor->ResetFault());
      FACEDYN_ASSIGN_OR_RETURN(const rig::PlatformReading reading, s.supervisor->ReadOnce());
      PrintReading(*s.supervisor, reading, o.json);
      return Status::Ok();
    };
  });
}

}  // namespace facedyn::app
