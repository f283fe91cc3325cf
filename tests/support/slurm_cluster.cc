#include "tests/support/slurm_cluster.h"

#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <sstream>
#include <string>
#include <thread>

extern char** environ;

namespace facedyn::testing {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr double kStartTimeoutS = 30.0;
constexpr double kStopTimeoutS = 10.0;
constexpr double kCancelTimeoutS = 5.0;
constexpr double kClientTimeoutS = 10.0;
constexpr int kLogTailLines = 25;
// Set in the daemons' environment (and so inherited by the slurmstepd processes slurmd starts,
// which outlive slurmd): how Stop() finds step daemons left from this cluster.
constexpr char kMarkerVariable[] = "FACEDYN_SLURM_CLUSTER";
constexpr char kPartition[] = "debug";

// `name` on PATH, else in the sbin folders (not on a non-login root's PATH everywhere); "".
std::string FindExecutable(const std::string& name) {
  std::vector<std::string> folders;
  if (const char* path = std::getenv("PATH")) {
    std::stringstream s(path);
    std::string folder;
    while (std::getline(s, folder, ':')) {
      if (!folder.empty()) folders.push_back(folder);
    }
  }
  for (const char* folder : {"/usr/sbin", "/sbin", "/usr/local/sbin", "/usr/bin", "/bin"}) {
    folders.push_back(folder);
  }
  for (const std::string& folder : folders) {
    const std::string candidate = folder + "/" + name;
    struct stat st;
    if (::stat(candidate.c_str(), &st) == 0 && S_ISREG(st.st_mode) &&
        ::access(candidate.c_str(), X_OK) == 0) {
      return candidate;
    }
  }
  return "";
}

std::string Tail(const std::string& path, int lines) {
  std::ifstream in(path);
  if (!in) return "(no such file)\n";
  std::vector<std::string> kept;
  std::string line;
  while (std::getline(in, line)) {
    kept.push_back(line);
    if (static_cast<int>(kept.size()) > lines) kept.erase(kept.begin());
  }
  std::string out;
  for (const std::string& l : kept) out += l + "\n";
  return out.empty() ? "(empty)\n" : out;
}

std::string ShellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'') {
      out += "'\\''";
    } else {
      out += c;
    }
  }
  return out + "'";
}

// True when nothing listens on or is bound to `port` on any IPv4 address (a bind without
// SO_REUSEADDR also fails while the port is in TIME_WAIT).
bool PortFree(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_ANY);
  address.sin_port = htons(static_cast<uint16_t>(port));
  const bool free = ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
  ::close(fd);
  return free;
}

// Two distinct free ports below the kernel's ephemeral range (32768-60999 by default), so an
// outgoing connection does not take one between this check and the daemon's bind.
bool PickPorts(int* first, int* second) {
  std::random_device rd;
  std::mt19937 rng(rd());
  std::uniform_int_distribution<int> pick(20000, 32767);
  std::vector<int> found;
  for (int attempt = 0; attempt < 200 && found.size() < 2; ++attempt) {
    const int port = pick(rng);
    if (std::find(found.begin(), found.end(), port) == found.end() && PortFree(port)) {
      found.push_back(port);
    }
  }
  if (found.size() < 2) return false;
  *first = found[0];
  *second = found[1];
  return true;
}

std::string ShortHostname() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "";
  std::string host = name;
  return host.substr(0, host.find('.'));
}

// The caller's environment without Slurm's own variables (a test run inside a Slurm job, or
// with SBATCH_PARTITION set, must not steer the private cluster), plus `extra`.
std::vector<std::string> ChildEnvironment(const std::vector<std::string>& extra) {
  std::vector<std::string> env;
  for (char** e = environ; *e; ++e) {
    const std::string entry = *e;
    if (entry.rfind("SLURM_", 0) == 0 || entry.rfind("SBATCH_", 0) == 0 ||
        entry.rfind("SQUEUE_", 0) == 0 || entry.rfind("SINFO_", 0) == 0 ||
        entry.rfind("SCONTROL_", 0) == 0 || entry.rfind(kMarkerVariable, 0) == 0) {
      continue;
    }
    env.push_back(entry);
  }
  env.insert(env.end(), extra.begin(), extra.end());
  return env;
}

std::vector<char*> CStrings(std::vector<std::string>& strings) {
  std::vector<char*> out;
  for (std::string& s : strings) out.push_back(s.data());
  out.push_back(nullptr);
  return out;
}

// In a forked child: closes every descriptor from 3 up.
void CloseDescriptorsFrom3() {
#ifdef SYS_close_range
  if (::syscall(SYS_close_range, 3U, ~0U, 0U) == 0) return;
#endif
  const long limit = std::min(::sysconf(_SC_OPEN_MAX), 65536L);
  for (int fd = 3; fd < limit; ++fd) ::close(fd);
}

// In a forked child: the state a daemon expects from its parent. Only async-signal-safe calls.
void PrepareChild(pid_t parent, int stdin_fd, int output_fd) {
  // The daemons end with the test: SIGTERM when the thread that forked them ends.
  ::prctl(PR_SET_PDEATHSIG, SIGTERM);
  if (::getppid() != parent) ::_exit(127);
  sigset_t none;
  sigemptyset(&none);
  ::sigprocmask(SIG_SETMASK, &none, nullptr);
  ::dup2(stdin_fd, 0);
  ::dup2(output_fd, 1);
  ::dup2(output_fd, 2);
  CloseDescriptorsFrom3();
}

// In a forked child, after a failed exec: says so in the daemon's log, where Start()'s error
// message quotes it.
[[noreturn]] void ExecOrExit(std::vector<char*>& argv, std::vector<char*>& envp) {
  ::execve(argv[0], argv.data(), envp.data());
  for (const char* part : {"exec failed: ", static_cast<const char*>(argv[0]), "\n"}) {
    const ssize_t written = ::write(2, part, std::strlen(part));
    static_cast<void>(written);
  }
  ::_exit(127);
}

std::string DescribeStatus(int status) {
  if (WIFEXITED(status)) return "exit code " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return "killed by signal " + std::to_string(WTERMSIG(status));
  return "status " + std::to_string(status);
}

void SleepS(double s) { std::this_thread::sleep_for(std::chrono::duration<double>(s)); }

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace

std::string SlurmUnavailableReason() {
  if (::geteuid() != 0) {
    return "a local Slurm cluster needs root (slurmd starts jobs as their user); running as uid " +
           std::to_string(::geteuid());
  }
  std::string missing;
  for (const char* name :
       {"munged", "slurmctld", "slurmd", "sbatch", "squeue", "scontrol", "scancel"}) {
    if (FindExecutable(name).empty()) missing += (missing.empty() ? "" : ", ") + std::string(name);
  }
  if (!missing.empty()) {
    return "not installed: " + missing + " (Debian packages slurm-wlm, munge)";
  }
  return "";
}

LocalSlurmCluster::~LocalSlurmCluster() { Stop(); }

std::string LocalSlurmCluster::Start(const std::string& dir) {
  if (started_ || !daemons_.empty()) return "this LocalSlurmCluster is already running";
  if (const std::string reason = SlurmUnavailableReason(); !reason.empty()) return reason;
  if (dir.empty()) return "no folder given";
  std::error_code ec;
  const fs::path absolute = fs::absolute(dir, ec).lexically_normal();
  dir_ = absolute.string();
  while (dir_.size() > 1 && dir_.back() == '/') dir_.pop_back();
  if (dir_.find_first_of(" \t\n\"'#=,") != std::string::npos) {
    return "folder " + dir_ + " has a character slurm.conf cannot carry (space, quote, # = ,)";
  }
  const std::string host = ShortHostname();
  if (host.empty()) return "gethostname failed";
  // Unix socket paths hold 107 characters: munged's socket, and slurmstepd's
  // <spool>/<node>_<job>.<step> (up to 10 + 1 + 10 digits).
  const std::string socket_path = dir_ + "/munge/munge.socket";
  const std::string spool_dir = dir_ + "/spool";
  const size_t longest = std::max(socket_path.size(), spool_dir.size() + 1 + host.size() + 22);
  if (longest >= sizeof(sockaddr_un::sun_path)) {
    return "folder " + dir_ + " is too long for the Unix sockets under it (" +
           std::to_string(longest) + " of " + std::to_string(sizeof(sockaddr_un::sun_path) - 1) +
           " characters)";
  }

  log_dir_ = dir_ + "/log";
  conf_path_ = dir_ + "/slurm.conf";
  const std::string munge_dir = dir_ + "/munge";
  const std::string state_dir = dir_ + "/state";
  for (const std::string& d : {dir_, munge_dir, state_dir, spool_dir, log_dir_}) {
    fs::create_directories(d, ec);
    if (!fs::is_directory(d)) return "cannot create " + d + ": " + ec.message();
  }
  // munged refuses a socket folder that others cannot search.
  ::chmod(munge_dir.c_str(), 0755);

  // A fresh key: the cluster must not accept credentials of the machine's munged.
  const std::string key_path = munge_dir + "/munge.key";
  {
    std::ifstream random("/dev/urandom", std::ios::binary);
    std::string key(1024, '\0');
    random.read(key.data(), static_cast<std::streamsize>(key.size()));
    if (!random) return "cannot read /dev/urandom";
    fs::remove(key_path, ec);
    const int fd = ::open(key_path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0400);
    if (fd < 0) return "cannot create " + key_path + ": " + std::strerror(errno);
    const bool written = ::write(fd, key.data(), key.size()) == static_cast<ssize_t>(key.size());
    ::close(fd);
    if (!written) return "cannot write " + key_path;
  }

  std::ofstream(dir_ + "/plugstack.conf", std::ios::trunc).close();

  int controller_port = 0;
  int node_port = 0;
  if (!PickPorts(&controller_port, &node_port)) return "found no two free TCP ports in 20000-32767";
  const long cpus = std::max(1L, ::sysconf(_SC_NPROCESSORS_ONLN));
  const long long memory_mb = std::max(1LL, static_cast<long long>(::sysconf(_SC_PHYS_PAGES)) *
                                                ::sysconf(_SC_PAGESIZE) / 2 / 1048576);

  {
    std::ofstream conf(conf_path_);
    conf << "# A private single-node cluster of facedyn's tests (tests/support/slurm_cluster.h).\n"
         << "ClusterName=facedyn" << controller_port << "\n"
         << "SlurmctldHost=" << host << "(127.0.0.1)\n"
         << "SlurmctldPort=" << controller_port << "\n"
         << "SlurmdPort=" << node_port << "\n"
         << "SlurmUser=root\n"
         << "SlurmdUser=root\n"
         << "AuthType=auth/munge\n"
         << "CredType=cred/munge\n"
         << "AuthInfo=socket=" << socket_path << "\n"
         << "StateSaveLocation=" << state_dir << "\n"
         << "SlurmdSpoolDir=" << spool_dir << "\n"
         << "SlurmctldPidFile=" << dir_ << "/slurmctld.pid\n"
         << "SlurmdPidFile=" << dir_ << "/slurmd.pid\n"
         << "SlurmctldLogFile=" << log_dir_ << "/slurmctld.log\n"
         << "SlurmdLogFile=" << log_dir_
         << "/slurmd.log\n"
         // Empty: no SPANK plugin from the machine's plugstack.conf.d in the jobs.
         << "PlugStackConfig=" << dir_ << "/plugstack.conf\n"
         << "ProctrackType=proctrack/linuxproc\n"
         << "TaskPlugin=task/none\n"
         << "JobAcctGatherType=jobacct_gather/none\n"
         << "AccountingStorageType=accounting_storage/none\n"
         << "JobCompType=jobcomp/none\n"
         << "SelectType=select/cons_tres\n"
         << "SelectTypeParameters=CR_CPU\n"
         << "MpiDefault=none\n"
         << "ReturnToService=2\n"
         // Batch jobs are scheduled as they are submitted or others end, not up to 3 s later.
         << "SchedulerParameters=batch_sched_delay=0\n"
         // The node counts as configured even where slurmd's hardware probe disagrees
         // (sockets x cores), instead of being drained.
         << "SlurmdParameters=config_overrides\n"
         // Cancelled jobs get SIGKILL 2 s after SIGTERM (30 s by default): Stop() stays fast.
         << "KillWait=2\n"
         << "NodeName=" << host << " NodeHostname=" << host << " NodeAddr=127.0.0.1 CPUs=" << cpus
         << " RealMemory=" << memory_mb << " State=UNKNOWN\n"
         << "PartitionName=" << kPartition << " Nodes=" << host
         << " Default=YES MaxTime=INFINITE State=UP\n";
    if (!conf.good()) return "cannot write " + conf_path_;
  }

  const auto start = Clock::now();
  // munged in the foreground logs to stderr; --log-file and --seed-file keep it off /var.
  // --force: as root munged would otherwise refuse a socket under a folder others cannot search
  // (a 0700 temp folder).
  if (std::string error = Spawn(
          "munged",
          {FindExecutable("munged"), "--foreground", "--force", "--key-file=" + key_path,
           "--socket=" + socket_path, "--pid-file=" + munge_dir + "/munged.pid",
           "--seed-file=" + munge_dir + "/munged.seed", "--log-file=" + log_dir_ + "/munged.log"});
      !error.empty()) {
    return Fail(error);
  }
  while (!fs::exists(socket_path)) {
    if (std::string exited = ExitedDaemon(); !exited.empty()) return Fail(exited);
    if (SecondsSince(start) > kStartTimeoutS) return Fail("munged made no socket in time");
    SleepS(0.02);
  }

  if (std::string error = Spawn("slurmctld", {FindExecutable("slurmctld"), "-D", "-f", conf_path_});
      !error.empty()) {
    return Fail(error);
  }
  // slurmd registers with the controller at start and retries only after a while: start it once
  // the controller answers.
  const std::string scontrol = FindExecutable("scontrol");
  for (;;) {
    std::string output;
    if (RunClient({scontrol, "ping"}, &output) == 0 && output.find(" is UP") != std::string::npos) {
      break;
    }
    if (std::string exited = ExitedDaemon(); !exited.empty()) return Fail(exited);
    if (SecondsSince(start) > kStartTimeoutS) {
      return Fail("slurmctld did not answer `scontrol ping` within " +
                  std::to_string(static_cast<int>(kStartTimeoutS)) + " s; last answer: " + output);
    }
    SleepS(0.1);
  }

  if (std::string error = Spawn("slurmd", {FindExecutable("slurmd"), "-D", "-f", conf_path_});
      !error.empty()) {
    return Fail(error);
  }
  for (;;) {
    std::string output;
    // One line per node; the state may carry flags (IDLE+NOT_RESPONDING, IDLE+DRAIN): only a
    // plain IDLE takes jobs.
    if (RunClient({scontrol, "-o", "show", "node", host}, &output) == 0 &&
        output.find(" State=IDLE ") != std::string::npos) {
      break;
    }
    if (std::string exited = ExitedDaemon(); !exited.empty()) return Fail(exited);
    if (SecondsSince(start) > kStartTimeoutS) {
      return Fail("node " + host + " did not become idle within " +
                  std::to_string(static_cast<int>(kStartTimeoutS)) + " s; last state: " + output);
    }
    SleepS(0.1);
  }
  started_ = true;
  return "";
}

std::string LocalSlurmCluster::Spawn(const std::string& name,
                                     const std::vector<std::string>& argv) {
  Daemon daemon;
  daemon.name = name;
  // slurmctld and slurmd write their own log (slurm.conf) and, in the foreground, a copy to
  // stderr; stderr also has what goes wrong before the log is open.
  daemon.log_path = log_dir_ + "/" + name + (name == "munged" ? ".log" : ".stderr");
  if (argv.empty() || argv[0].empty()) return name + " is not installed";
  std::vector<std::string> args = argv;
  std::vector<std::string> env =
      ChildEnvironment({"SLURM_CONF=" + conf_path_, std::string(kMarkerVariable) + "=" + dir_});
  std::vector<char*> argv_c = CStrings(args);
  std::vector<char*> env_c = CStrings(env);
  const int output_fd =
      ::open(daemon.log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  const int null_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  if (output_fd < 0 || null_fd < 0) {
    if (output_fd >= 0) ::close(output_fd);
    if (null_fd >= 0) ::close(null_fd);
    return "cannot open " + daemon.log_path + " or /dev/null";
  }
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    PrepareChild(parent, null_fd, output_fd);
    ExecOrExit(argv_c, env_c);
  }
  ::close(output_fd);
  ::close(null_fd);
  if (pid < 0) return "fork for " + name + " failed: " + std::strerror(errno);
  daemon.pid = pid;
  daemons_.push_back(daemon);
  return "";
}

std::string LocalSlurmCluster::ExitedDaemon() {
  for (Daemon& daemon : daemons_) {
    if (daemon.pid <= 0) continue;
    int status = 0;
    if (::waitpid(daemon.pid, &status, WNOHANG) == daemon.pid) {
      daemon.pid = -1;
      return daemon.name + " exited (" + DescribeStatus(status) + ")";
    }
  }
  return "";
}

std::string LocalSlurmCluster::Fail(const std::string& what) {
  std::string message = "local Slurm cluster in " + dir_ + " did not start: " + what + "\n";
  for (const Daemon& daemon : daemons_) {
    message +=
        "--- last lines of " + daemon.log_path + " ---\n" + Tail(daemon.log_path, kLogTailLines);
  }
  Stop();
  return message;
}

int LocalSlurmCluster::RunClient(const std::vector<std::string>& argv, std::string* output) const {
  output->clear();
  if (argv.empty() || argv[0].empty()) return -1;
  std::vector<std::string> args = argv;
  std::vector<std::string> env = ChildEnvironment({"SLURM_CONF=" + conf_path_});
  std::vector<char*> argv_c = CStrings(args);
  std::vector<char*> env_c = CStrings(env);
  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_CLOEXEC) != 0) return -1;
  const int null_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    PrepareChild(parent, null_fd, pipe_fds[1]);
    ExecOrExit(argv_c, env_c);
  }
  ::close(pipe_fds[1]);
  if (null_fd >= 0) ::close(null_fd);
  if (pid < 0) {
    ::close(pipe_fds[0]);
    return -1;
  }
  // Read until EOF or the deadline; a hung client is killed.
  const auto start = Clock::now();
  ::fcntl(pipe_fds[0], F_SETFL, O_NONBLOCK);
  char buffer[4096];
  for (;;) {
    const ssize_t n = ::read(pipe_fds[0], buffer, sizeof(buffer));
    if (n > 0) {
      output->append(buffer, static_cast<size_t>(n));
      continue;
    }
    if (n == 0) break;
    if (errno != EAGAIN && errno != EINTR) break;
    if (SecondsSince(start) > kClientTimeoutS) {
      ::kill(pid, SIGKILL);
      break;
    }
    SleepS(0.005);
  }
  ::close(pipe_fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

bool LocalSlurmCluster::running() const {
  if (!started_ || daemons_.empty()) return false;
  for (const Daemon& daemon : daemons_) {
    if (daemon.pid <= 0) return false;
    siginfo_t info{};
    // WNOWAIT: look without reaping, so Stop() still collects the status.
    if (::waitid(P_PID, static_cast<id_t>(daemon.pid), &info, WEXITED | WNOHANG | WNOWAIT) != 0 ||
        info.si_pid != 0) {
      return false;
    }
  }
  return true;
}

void LocalSlurmCluster::CancelJobs() {
  // Only with a controller and a node alive: otherwise no job can be running here, and the
  // clients would wait for their timeouts.
  if (daemons_.size() < 3) return;
  for (const Daemon& daemon : daemons_) {
    if (daemon.pid <= 0 || ::kill(daemon.pid, 0) != 0) return;
  }
  const std::string squeue = FindExecutable("squeue");
  std::string output;
  if (RunClient({squeue, "-h", "-o", "%A"}, &output) != 0) return;
  std::vector<std::string> cancel = {FindExecutable("scancel")};
  std::stringstream ids(output);
  std::string id;
  while (ids >> id) cancel.push_back(id);
  if (cancel.size() == 1) return;
  RunClient(cancel, &output);
  const auto start = Clock::now();
  while (SecondsSince(start) < kCancelTimeoutS) {
    if (RunClient({squeue, "-h", "-o", "%A"}, &output) != 0 ||
        output.find_first_not_of(" \n") == std::string::npos) {
      return;
    }
    SleepS(0.1);
  }
}

void LocalSlurmCluster::StopDaemon(Daemon* daemon) {
  if (daemon->pid <= 0) return;
  ::kill(daemon->pid, SIGTERM);
  const auto start = Clock::now();
  for (;;) {
    int status = 0;
    const pid_t reaped = ::waitpid(daemon->pid, &status, WNOHANG);
    if (reaped == daemon->pid || (reaped < 0 && errno == ECHILD)) break;
    if (SecondsSince(start) > kStopTimeoutS) {
      ::kill(daemon->pid, SIGKILL);
      while (::waitpid(daemon->pid, &status, 0) < 0 && errno == EINTR) {
      }
      break;
    }
    SleepS(0.01);
  }
  daemon->pid = -1;
}

void LocalSlurmCluster::KillStrayStepDaemons() {
  if (dir_.empty()) return;
  std::string marker = std::string(kMarkerVariable) + "=" + dir_;
  marker.push_back('\0');
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || name.find_first_not_of("0123456789") != std::string::npos) continue;
    const pid_t pid = static_cast<pid_t>(std::stol(name));
    if (pid == ::getpid()) continue;
    std::ifstream in(entry.path() / "environ", std::ios::binary);
    std::string environment((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (environment.rfind(marker, 0) == 0 ||
        environment.find(std::string(1, '\0') + marker) != std::string::npos) {
      ::kill(pid, SIGKILL);
    }
  }
}

void LocalSlurmCluster::Stop() {
  CancelJobs();
  // The node first, the controller next, munged (which both need to talk) last.
  for (auto it = daemons_.rbegin(); it != daemons_.rend(); ++it) StopDaemon(&*it);
  KillStrayStepDaemons();
  daemons_.clear();
  started_ = false;
}

std::vector<std::pair<std::string, std::string>> LocalSlurmCluster::Environment() const {
  if (!started_) return {};
  return {{"SLURM_CONF", conf_path_}};
}

std::string LocalSlurmCluster::EnvironmentPrefix() const {
  std::string prefix;
  for (const auto& [name, value] : Environment()) prefix += name + "=" + ShellQuote(value) + " ";
  return prefix;
}

std::string LocalSlurmCluster::partition() const { return kPartition; }

std::string LocalSlurmCluster::log_dir() const { return log_dir_; }

}  // namespace facedyn::testing
