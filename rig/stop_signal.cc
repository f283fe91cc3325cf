#include "rig/stop_signal.h"

#include <csignal>

namespace facedyn::rig {
namespace {

std::atomic<bool> g_stop_requested{false};
static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs a lock-free flag");

extern "C" void OnStopSignal(int) { g_stop_requested.store(true); }

}  // namespace

const int kStopSignals[4] = {SIGINT, SIGTERM, SIGHUP, SIGQUIT};

const std::atomic<bool>* InstallStopSignalHandlers() {
  struct sigaction action {};
  action.sa_handler = OnStopSignal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = 0;  // no SA_RESTART: a blocking sleep or read returns early
  for (int signal_number : kStopSignals) sigaction(signal_number, &action, nullptr);
  // A closed pipe on stdout or stderr (`facedyn sweep ... | head -n 1`) must not kill the
  // process mid-move: with SIGPIPE ignored, the write fails with EPIPE and the run goes on.
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  sigemptyset(&ignore.sa_mask);
  sigaction(SIGPIPE, &ignore, nullptr);
  return &g_stop_requested;
}

void ClearStopRequest() { g_stop_requested.store(false); }

}  // namespace facedyn::rig
