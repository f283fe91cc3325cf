// Replicates: every figure that compares two methods is the mean and spread over at least 3
// seeds (takes and initialisation), and a difference inside the spread is a tie, never a win.
#pragma once

#include <cstdint>
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

// The general form: `replicates[r]` is replicate r's array of entries {"take", optional
// "protocol", "methods": {name: {figure: mm}}}; entries are matched by take name. Per take,
// each method's `figure` as a Spread ("mean_mm", "sd_mm", "min_mm", "max_mm", "replicates"),
// and each fitted method (name starting with one of `learned_prefixes`) against every other
// method that is not fitted, as a verdict (CompareLowerIsBetter). Returns the array of take
// summaries.
Json SummariseMethodReplicates(const std::vector<Json>& replicates, const std::string& figure,
                               const std::vector<std::string>& learned_prefixes);

// `facedyn demo --seeds`: one demo dynamics stage per seed (app/demo_dynamics.h's JSON: the
// sections "removal", "removal_performance", "removal_walk", "synthesis" and "retarget"), each
// with its own training takes, new test performance and walk, and network initialisation.
// Returns {"replicates", "seeds", "rule", "removal": per protocol (held-out frequency,
// performance, walk) every method's jiggle_mean_mm plus "lower_reference" (Eq. 7 with the exact
// offsets in the estimated skull frame) with F's verdicts, "resynthesis": Fig. 7's residual
// on the held-out take and on the held-out performance, F's removal resynthesised by H and by
// the modal synthesis, against removal without synthesis, "new_motion_synthesis" and "retarget": each method's
// offset_mean_mm with the verdicts of H and of the modal synthesis}. Sections a stage lacks are left out of its replicate.
Json SummariseDemoReplicates(const std::vector<Json>& stages, const std::vector<uint64_t>& seeds);

// Prints a replicate summary (SummariseDemoReplicates's JSON) as tables on stdout: per section
// and protocol, each method's mean and sd, and the learned method's verdicts.
void PrintReplicateSummary(const Json& summary);

}  // namespace facedyn::eval
