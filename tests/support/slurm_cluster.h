// A private Slurm cluster on localhost for tests: munged, slurmctld and slurmd started as child
// processes of the test, everything they read or write under one folder.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace facedyn::testing {

// One controller and one compute node (this machine) with one default partition, reachable only
// through the slurm.conf in its folder. The class owns its daemons by pid (it forks and execs
// them in the foreground), so it can stop exactly what it started and nothing else, and the
// cluster cannot be mistaken for, or disturb, a system-wide Slurm or munge:
//   - munged runs with its own random key and its own socket (<dir>/munge/munge.socket);
//     slurm.conf names that socket in AuthInfo, which auth/munge and cred/munge both read,
//     so clients need no munge setting of their own;
//   - slurmctld and slurmd listen on two ports picked free at Start (20000-32767, below the
//     kernel's ephemeral range), so two clusters, or a stray daemon, do not collide;
//   - nothing under /etc/slurm or /etc/munge is read: plugstack.conf is an empty file beside
//     slurm.conf, and the plugins chosen (proctrack/linuxproc, task/none) need no cgroup.conf.
// The node is named after `hostname -s` (slurmd finds its node by host name; Debian's slurmd is
// built without -N) and is reached at 127.0.0.1. It has the machine's online CPUs, and
// select/cons_tres with CR_CPU, so several 1-CPU jobs run at once. Jobs run as the submitting
// user (tests run as root).
//
// The daemons get SIGTERM if the thread that called Start() ends (PR_SET_PDEATHSIG), so a
// crashed test does not leave a cluster behind: call Start() from a thread that outlives the
// cluster (a test body does).
class LocalSlurmCluster {
 public:
  LocalSlurmCluster() = default;
  LocalSlurmCluster(const LocalSlurmCluster&) = delete;
  LocalSlurmCluster& operator=(const LocalSlurmCluster&) = delete;

  // Starts munged, slurmctld and slurmd on localhost, every file (munge key, sockets, pid files,
  // slurm.conf, state/spool dirs, daemon logs) under `dir` (created). On success the cluster
  // has one node in state idle with the machine's CPUs and a default partition, and
  // getenv-visible configuration is NOT changed (callers use Environment()). Returns "" on
  // success and the cluster is running; otherwise an explanation of why not (not root, a binary
  // missing, a daemon failed: with the tail of its log) and nothing is left running.
  // Returns in well under a second here (gives up after 30 s); the controller schedules its
  // first job about 3 s after it started, later ones within a second of submission or of a
  // job's end. `dir` must be free of whitespace, quotes, '#', '=' and ',', and short enough for
  // the Unix sockets under it (about 75 characters less the host name's length).
  std::string Start(const std::string& dir);
  // Stop().
  ~LocalSlurmCluster();
  // Cancels the cluster's jobs (waiting up to 5 s for them to end), then stops every daemon this
  // object started, by pid: SIGTERM, wait up to 10 s, SIGKILL; then kills any slurmstepd left
  // from this cluster. Idempotent.
  void Stop();
  // True between a successful Start() and Stop(), while none of the three daemons has exited.
  bool running() const;
  // Variables a client process (sbatch, squeue, scontrol, scancel, sinfo) needs to reach this
  // cluster: {"SLURM_CONF", <dir>/slurm.conf}. Empty before a successful Start() and after
  // Stop().
  std::vector<std::pair<std::string, std::string>> Environment() const;
  // The same as a prefix for a shell command line: "SLURM_CONF='<dir>/slurm.conf' ".
  std::string EnvironmentPrefix() const;
  // The default partition's name ("debug").
  std::string partition() const;
  // Where the daemons' logs are (<dir>/log: munged.log, slurmctld.log, slurmd.log).
  std::string log_dir() const;

 private:
  struct Daemon {
    std::string name;
    std::string log_path;
    int pid = -1;
  };
  // Forks and execs one daemon with stdout and stderr in its log; "" or why not.
  std::string Spawn(const std::string& name, const std::vector<std::string>& argv);
  // Why Start() failed: `what`, then the tail of every started daemon's log; stops everything.
  std::string Fail(const std::string& what);
  // The first daemon that has exited, as "<name> exited (...)", or "".
  std::string ExitedDaemon();
  // Runs a Slurm client of this cluster (with SLURM_CONF set), output captured; exit code.
  int RunClient(const std::vector<std::string>& argv, std::string* output) const;
  void CancelJobs();
  void StopDaemon(Daemon* daemon);
  void KillStrayStepDaemons();

  std::string dir_;
  std::string conf_path_;
  std::string log_dir_;
  std::vector<Daemon> daemons_;  // In start order: munged, slurmctld, slurmd.
  bool started_ = false;
};

// Why a Slurm test cannot run here ("" when it can): not root, or
// munged/slurmctld/slurmd/sbatch/squeue/scontrol/scancel missing.
std::string SlurmUnavailableReason();

}  // namespace facedyn::testing
