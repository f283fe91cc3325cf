// facedyn: facial performance capture with secondary dynamics (see README.md).
//
// Exit codes: 0 success, 1 the command failed (the message says why), 2 bad command line.

#include <cstdio>
#include <exception>
#include <new>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "app/command.h"
#include "core/log.h"
#include "core/progress.h"
#include "facedyn_version.h"

int main(int argc, char** argv) {
  using namespace facedyn;
  CLI::App cli{"facedyn — facial capture with secondary dynamics: drive the platform, capture,\n"
               "reconstruct, and remove or synthesise skin jiggle. See README.md.",
               "facedyn"};
  cli.set_version_flag("--version", std::string("facedyn ") + FACEDYN_VERSION + " (" +
                                        FACEDYN_GIT_REVISION + ")");
  bool quiet = false;
  bool verbose = false;
  cli.add_flag("-q,--quiet", quiet, "Only warnings and errors; no progress bars");
  cli.add_flag("-v,--verbose", verbose, "Debug logging");
  cli.require_subcommand(1);
  cli.fallthrough();  // --quiet/--verbose may follow the subcommand

  app::CommandRunner selected;
  app::AddTakeCommands(cli, &selected);
  app::AddExportCommand(cli, &selected);
  app::AddViewCommand(cli, &selected);
  app::AddSimCommands(cli, &selected);
  app::AddDynamicsCommands(cli, &selected);
  app::AddSolveCommands(cli, &selected);
  app::AddDetailCommands(cli, &selected);
  app::AddTwinCommands(cli, &selected);
  app::AddRigCommands(cli, &selected);
  app::AddSweepCommand(cli, &selected);
  app::AddCalibrateCommand(cli, &selected);
  app::AddReconstructCommand(cli, &selected);
  app::AddCaptureCommands(cli, &selected);
  app::AddProcessCommand(cli, &selected);
  app::AddDemoCommand(cli, &selected);
  app::AddReportCommand(cli, &selected);

  try {
    cli.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help, --version
    return cli.exit(e);
  } catch (const CLI::ParseError& e) {
    cli.exit(e);
    return 2;
  }

  InitLogging(quiet ? Verbosity::kQuiet : verbose ? Verbosity::kVerbose : Verbosity::kNormal);
  if (quiet) SetDefaultProgressMode(ProgressMode::kSilent);
  if (!selected) {
    std::fprintf(stderr, "facedyn: nothing to do (see facedyn --help)\n");
    return 2;
  }
  // Last line of defence: an exception that escaped a command (a library's bad_alloc on a
  // hostile size, a parser's throw) becomes a message and exit 1, never an abort. The command's
  // objects are destroyed while the exception unwinds, so a RigSupervisor ramps its platform to
  // a stop (or leaves the drive's watchdog armed) before this prints.
  Status status;
  try {
    status = selected();
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "facedyn: error: out of memory (an input asked for more than fits)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "facedyn: error: unexpected failure: %s\n", e.what());
    return 1;
  } catch (...) {
    std::fprintf(stderr, "facedyn: error: unexpected failure (unknown exception)\n");
    return 1;
  }
  if (!status.ok()) {
    std::fprintf(stderr, "facedyn: error: %s\n", status.message().c_str());
    return 1;
  }
  return 0;
}
