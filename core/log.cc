#include "core/log.h"

#include <atomic>

#include <spdlog/sinks/stdout_color_sinks.h>

namespace facedyn {
namespace {
std::atomic<Verbosity> g_verbosity{Verbosity::kNormal};
}

void InitLogging(Verbosity verbosity) {
  g_verbosity = verbosity;
  auto logger = spdlog::get("facedyn");
  if (!logger) {
    logger = spdlog::stderr_color_mt("facedyn");
    logger->set_pattern("%^[%L]%$ %v");
    spdlog::set_default_logger(logger);
  }
  switch (verbosity) {
    case Verbosity::kQuiet: logger->set_level(spdlog::level::warn); break;
    case Verbosity::kNormal: logger->set_level(spdlog::level::info); break;
    case Verbosity::kVerbose: logger->set_level(spdlog::level::debug); break;
  }
}

Verbosity CurrentVerbosity() { return g_verbosity; }

}  // namespace facedyn
