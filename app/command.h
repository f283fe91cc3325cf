// How subcommands plug into the `facedyn` executable. Each Add*Commands function declares
// its CLI11 subcommands and, when one of them is chosen on the command line, stores the
// work to run in *selected; main() runs it after parsing and turns its Status into the exit
// code. app/ wires modules together and owns no algorithm.
#pragma once

#include <functional>

#include <CLI/CLI.hpp>

#include "core/face_rig.h"
#include "core/status.h"

namespace facedyn::app {

using CommandRunner = std::function<Status()>;

void AddTakeCommands(CLI::App& app, CommandRunner* selected);
void AddExportCommand(CLI::App& app, CommandRunner* selected);
void AddViewCommand(CLI::App& app, CommandRunner* selected);
void AddDemoCommand(CLI::App& app, CommandRunner* selected);
void AddReportCommand(CLI::App& app, CommandRunner* selected);  // the demo's report again
void AddSimCommands(CLI::App& app, CommandRunner* selected);
void AddDynamicsCommands(CLI::App& app, CommandRunner* selected);
void AddSolveCommands(CLI::App& app, CommandRunner* selected);  // solve train|run|apply (FDLS)
void AddRigCommands(CLI::App& app, CommandRunner* selected);
void AddSweepCommand(CLI::App& app, CommandRunner* selected);
void AddCalibrateCommand(CLI::App& app, CommandRunner* selected);
void AddReconstructCommand(CLI::App& app, CommandRunner* selected);
void AddCaptureCommands(CLI::App& app, CommandRunner* selected);  // capture, session check
void AddDetailCommands(CLI::App& app, CommandRunner* selected);   // detail train, detail apply
void AddProcessCommand(CLI::App& app, CommandRunner* selected);   // a session as a job graph
void AddTwinCommands(CLI::App& app, CommandRunner* selected);     // twin fit (physics/twin.h)
// train-removal, remove, train-synthesis, synthesize, retarget under `facedyn dynamics`.
void AddDynamicsNetworkCommands(CLI::App* dynamics, CommandRunner* selected);

// A FaceRig from a command-line spec: "procedural" (the embedded default, as `sim perform`
// uses it) or a FaceRig folder (`facedyn sim face --out`).
StatusOr<FaceRig> LoadFace(const std::string& spec);

}  // namespace facedyn::app
