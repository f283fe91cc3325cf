// `facedyn rig serve-sim|set|stop|status|reset`: the platform drive from the command line.

#include <chrono>
#include <csignal>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "app/command.h"
#include "rig/drive_client.h"
#include "rig/drive_profile.h"
#include "rig/modbus_transport.h"
#include "sim/drive_sim.h"

namespace facedyn::app {
namespace {

volatile std::sig_atomic_t g_stop_requested = 0;
extern "C" void RequestStop(int) { g_stop_requested = 1; }

struct RigOptions {
  std::string profile;
  std::string tcp;
  double hz = 0.0;
  bool json = false;
  double timeout_s = 0.5;
  int retries = 2;
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
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("drive     %s\nrunning   %s\noutput    %.2f Hz\nfault     %s\n",
                client.profile().name.c_str(), status.running ? "yes" : "no", status.output_hz,
                status.faulted ? status.fault_text.c_str() : "none");
  }
  return Status::Ok();
}

void AddConnectionOptions(CLI::App* command, RigOptions* options) {
  command->add_option("--profile", options->profile, "Drive profile YAML (config/drives/*.yaml)")
      ->required();
  command->add_option("--tcp", options->tcp, "Drive (or gateway) address HOST:PORT")->required();
  command->add_option("--timeout", options->timeout_s, "Response timeout in seconds")->capture_default_str();
  command->add_option("--retries", options->retries, "Extra attempts per request")->capture_default_str();
}

}  // namespace

void AddRigCommands(CLI::App& app, CommandRunner* selected) {
  auto* rig_command = app.add_subcommand("rig", "The vibrating platform's drive over Modbus");
  rig_command->require_subcommand(1);

  struct ServeOptions {
    std::string profile;
    std::string tcp = "127.0.0.1:5020";
    double seconds = 0.0;
    sim::DriveSimOptions sim;
  };
  auto serve = std::make_shared<ServeOptions>();
  auto* serve_command = rig_command->add_subcommand(
      "serve-sim", "Run a simulated drive behind a real Modbus TCP server (port 0: any free port)");
  serve_command->add_option("--profile", serve->profile, "Drive profile YAML whose map to serve")->required();
  serve_command->add_option("--tcp", serve->tcp, "Listen address HOST:PORT")->capture_default_str();
  serve_command->add_option("--seconds", serve->seconds, "Stop after this long (0: until Ctrl-C)")
      ->capture_default_str();
  serve_command->add_option("--accel-hz-per-s", serve->sim.model.accel_hz_per_s, "Motor ramp rate")
      ->capture_default_str();
  serve_command->add_option("--watchdog-s", serve->sim.model.watchdog_s,
                            "Comm watchdog: stop when no request for this long (0: off)")
      ->capture_default_str();
  serve_command->callback([serve, selected] {
    *selected = [serve]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(const rig::DriveProfile profile, rig::LoadDriveProfile(serve->profile));
      rig::TransportOptions endpoint;
      FACEDYN_RETURN_IF_ERROR(rig::ParseTcpEndpoint(serve->tcp, &endpoint));
      sim::DriveSimOptions options = serve->sim;
      options.host = endpoint.host;
      options.port = endpoint.port;
      FACEDYN_ASSIGN_OR_RETURN(auto server, sim::DriveSim::Start(profile, options));
      // The port goes to stdout so scripts can start us with port 0 and read where we are.
      std::printf("listening %s:%d profile %s\n", server->host().c_str(), server->port(),
                  profile.name.c_str());
      std::fflush(stdout);
      std::signal(SIGINT, RequestStop);
      std::signal(SIGTERM, RequestStop);
      const auto start = std::chrono::steady_clock::now();
      while (!g_stop_requested) {
        if (serve->seconds > 0.0 &&
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= serve->seconds) {
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
      spdlog::info("simulated drive served {} requests", server->requests_served());
      return Status::Ok();
    };
  });

  auto set_options = std::make_shared<RigOptions>();
  auto* set_command = rig_command->add_subcommand("set", "Set the frequency (6-11 Hz) and start the drive");
  AddConnectionOptions(set_command, set_options.get());
  set_command->add_option("--hz", set_options->hz, "Frequency in Hz")->required();
  set_command->add_flag("--json", set_options->json, "Print the resulting status as JSON");
  set_command->callback([set_options, selected] {
    *selected = [set_options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(Connection c, Connect(*set_options));
      FACEDYN_RETURN_IF_ERROR(c.client->SetFrequencyHz(set_options->hz));
      FACEDYN_RETURN_IF_ERROR(c.client->Start());
      return PrintStatus(*c.client, set_options->json);
    };
  });

  auto stop_options = std::make_shared<RigOptions>();
  auto* stop_command = rig_command->add_subcommand("stop", "Stop the drive (ramp to stop)");
  AddConnectionOptions(stop_command, stop_options.get());
  stop_command->add_flag("--json", stop_options->json, "Print the resulting status as JSON");
  stop_command->callback([stop_options, selected] {
    *selected = [stop_options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(Connection c, Connect(*stop_options));
      FACEDYN_RETURN_IF_ERROR(c.client->Stop());
      return PrintStatus(*c.client, stop_options->json);
    };
  });

  auto status_options = std::make_shared<RigOptions>();
  auto* status_command = rig_command->add_subcommand("status", "Running, output frequency and fault");
  AddConnectionOptions(status_command, status_options.get());
  status_command->add_flag("--json", status_options->json, "Print JSON on stdout");
  status_command->callback([status_options, selected] {
    *selected = [status_options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(Connection c, Connect(*status_options));
      return PrintStatus(*c.client, status_options->json);
    };
  });

  auto reset_options = std::make_shared<RigOptions>();
  auto* reset_command = rig_command->add_subcommand("reset", "Acknowledge a drive trip (explicit only)");
  AddConnectionOptions(reset_command, reset_options.get());
  reset_command->add_flag("--json", reset_options->json, "Print the resulting status as JSON");
  reset_command->callback([reset_options, selected] {
    *selected = [reset_options]() -> Status {
      FACEDYN_ASSIGN_OR_RETURN(Connection c, Connect(*reset_options));
      FACEDYN_RETURN_IF_ERROR(c.client->ResetFault());
      return PrintStatus(*c.client, reset_options->json);
    };
  });
}

}  // namespace facedyn::app
