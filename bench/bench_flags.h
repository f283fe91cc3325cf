// Command-line values of the bench programs: a flag's value is checked, and a bad one exits 2
// naming the program, the flag and the value (atof/atoi would turn a typo into 0, and
// std::stod would throw and abort).
#pragma once

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace facedyn::bench {

// A finite number.
inline double FlagNumber(const char* program, const std::string& flag, const char* text) {
  char* end = nullptr;
  const double value = std::strtod(text, &end);
  if (end == text || *end != '\0' || !std::isfinite(value)) {
    std::fprintf(stderr, "%s: %s: '%s' is not a number\n", program, flag.c_str(), text);
    std::exit(2);
  }
  return value;
}

// A non-negative integer.
inline long long FlagInteger(const char* program, const std::string& flag, const char* text) {
  char* end = nullptr;
  const long long value = std::strtoll(text, &end, 10);
  if (end == text || *end != '\0' || value < 0) {
    std::fprintf(stderr, "%s: %s: '%s' is not a non-negative integer\n", program, flag.c_str(),
                 text);
    std::exit(2);
  }
  return value;
}

}  // namespace facedyn::bench
