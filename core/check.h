// CHECK-style assertions for programmer errors (STYLE.md §5): a violated precondition is a
// bug, not bad input, so it aborts with the condition, file, line and a message. Bad input
// never reaches these; it is reported through Status (core/status.h).
#pragma once

#include <string>

namespace facedyn::internal {
[[noreturn]] void CheckFailed(const char* condition, const char* file, int line,
                              const std::string& message);
}  // namespace facedyn::internal

#define FACEDYN_CHECK(condition, ...)                                                   \
  do {                                                                                 \
    if (!(condition)) {                                                                \
      ::facedyn::internal::CheckFailed(#condition, __FILE__, __LINE__,                 \
                                       ::std::string(__VA_ARGS__));                   \
    }                                                                                  \
  } while (false)
