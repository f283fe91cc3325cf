// Replicates: every figure that compares two methods is the mean and spread over at least 3
// seeds (takes and initialisation), and a difference inside the spread is a tie, never a win.
#pragma once

#include <string>
#include <vector>

#include "core/json_io.h"

namespace facedyn::eval {

struct Spread {
  int count = 0;
  double mean = 0.0;
  double sd = 0.0;  // sample standard deviation (n - 1); 0 for one value
  double min = 0.0, max = 0.0;
};
Spread SpreadOf(const std::vector<double>& values);

// "lower" when a's mean is below b's by more than the larger of their standard deviations,
// "higher" when above by more than that, else "tie". Fewer than 3 replicates on either side:
// "too few replicates" (no verdict).
std::string CompareLowerIsBetter(const Spread& a, const Spread& b);

// Per removal take of dynamics studies run with different seeds (RunDynamicsStudy's JSON,
// "removal" array, matched by take name, keeping its "protocol"): each method's jiggle_mean_mm
// as a Spread, and each learned method (names starting "F") against every baseline as a
// verdict. Takes or methods
// missing from some replicate are summarised over the replicates that have them.
Json SummariseRemovalReplicates(const std::vector<Json>& studies);

}  // namespace facedyn::eval
