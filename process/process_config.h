// PROCESS.yaml: what `facedyn process` does with a capture session (config/process/).
//
// A session's reprocessing is a fixed graph of facedyn's own commands (process/job_graph.h):
//   per take:            reconstruct
//   after those takes:   train-removal (F), then train-synthesis (H)
//   independent:         train-solver (unless a trained solver is named)
//   per take:            remove (with F) -> solve (with the solver) -> export
// The file chooses the takes, the subject's face, and each step's options; every field has a
// default, so an empty file processes every complete take with the paper's settings.
#pragma once

#include <string>
#include <vector>

#include "core/status.h"

namespace facedyn::process {

struct ProcessConfig {
  std::string source_path;
  // FaceRig folder of the subject (relative paths are relative to this file), or "procedural".
  std::string face = "procedural";
  // Session take names to process: shell-style patterns ("*", "smile_*"), matched in order.
  std::vector<std::string> takes = {"*"};

  struct Reconstruct {
    double marker_diameter_px = 8.0;
    bool bright_markers = false;
    std::string calibration;  // "" = the session's calibration.yaml
  } reconstruct;

  struct Removal {
    bool enabled = true;
    std::vector<std::string> train_takes = {"*"};  // patterns among the processed takes
    std::string targets = "moving-average";        // train-removal --targets
    int epochs = 250;
  } removal;

  struct Synthesis {
    bool enabled = true;  // needs removal
    int epochs = 30;
  } synthesis;

  struct Solve {
    bool enabled = true;  // needs removal: solves the quasistatic take
    std::string model;    // a trained solver folder; "" = train one on `face`
    int epochs = 0;       // solve train --epochs (0: the region tables' value)
  } solve;

  struct Export {
    std::vector<std::string> formats = {"pc2"};  // facedyn export --format, per take
  } exports;

  // Training seed and LibTorch threads per step. One thread by default: the same inputs then
  // give byte-identical models on every machine of a cluster.
  unsigned seed = 1;
  int threads = 1;

  struct Slurm {
    std::string partition;  // "" = the cluster's default
    std::string account;
    int cpus_per_task = 1;
    std::string time_limit;  // sbatch --time, "" = the partition's
  } slurm;
};

// Reads and checks PROCESS.yaml; errors name the file, line and field. Unknown fields are errors.
StatusOr<ProcessConfig> LoadProcessConfig(const std::string& path);

// True when `name` matches the shell-style pattern (`*`, `?`, `[...]`; fnmatch(3)).
bool MatchesAnyPattern(const std::string& name, const std::vector<std::string>& patterns);

}  // namespace facedyn::process
