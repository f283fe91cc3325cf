// Evaluation of a quasistatic estimate against a truth take: per-vertex Euclidean error
// |y_pred(t) - y_true(t)| (mm) at every frame, summarised as mean, 95th percentile and max over
// the whole face and over each FaceRig region, with the same figures for each baseline
// (baselines.h) computed from the dynamic input. The truth is normally the simulator's exact
// "quasistatic" channel (sim/performance.h), which lets facedyn measure what Zoss et al. 2020
// could only estimate (their Fig. 5 reports average error).
//
// Scored frames (dynamics/training_frames.h ScoredFrames): those whose feature window
// (round(0.08 s * fps)) lies inside the take, starts at frame 1 or later and, for a
// held-expression take, after its hold_start_s — so no method is scored where every windowed
// method reads replicated edge frames, nor charged for smearing an onset that a held-expression
// protocol leaves out of training. An explicit skip_edge_frames keeps the old symmetric skip.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/pc2.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/baselines.h"
#include "dynamics/training_frames.h"

namespace facedyn::eval {

struct ErrorStats {
  long count = 0;  // (vertex, frame) pairs
  double mean_mm = 0.0;
  double p95_mm = 0.0;  // linear interpolation between order statistics (position 0.95 (n-1))
  double max_mm = 0.0;
};

// Mean, 95th percentile and max of `errors_mm` (reordered in place). Empty gives zeros.
ErrorStats ComputeErrorStats(std::vector<float>* errors_mm);

struct ErrorReport {
  std::string name;  // "prediction", or a baseline name
  ErrorStats face;
  std::map<std::string, ErrorStats> regions;  // empty without a FaceRig
};

struct EvaluateOptions {
  // Truth channel of the truth take; "positions" compares against its positions.
  std::string truth_channel = "quasistatic";
  int skip_edge_frames = -1;  // frames left out at each end; -1: ScoredFrames(truth, window)
  double window_s = 0.08;     // default skip, and the moving-average baseline's window
  dynamics::BaselineOptions baselines;
  // truth_channel non-empty, skip_edge_frames >= -1, window_s in [0, 1], baselines valid.
  Status Check() const;
};

// Errors of one point cache against another over `frames`. Errors name what differs (vertex
// count, frame count), a FaceRig of another vertex count, or an empty or out-of-range range.
StatusOr<ErrorReport> ComparePositions(const PointCache& predicted, const PointCache& truth,
                                       const FaceRig* rig, dynamics::FrameRange frames,
                                       const std::string& name);

struct Evaluation {
  std::string truth_channel;
  int frame_count = 0;
  int vertex_count = 0;
  int skip_edge_frames = 0;  // the window margin
  dynamics::FrameRange scored;  // the frames every figure is over
  double rule_cutoff_hz = 0.0;    // the "lowpass" baseline's cutoff (with an input)
  double oracle_cutoff_hz = 0.0;  // "lowpass_oracle"'s (with an input)
  std::vector<ErrorReport> reports;  // the prediction first, then each baseline
};

// The prediction's positions against the truth's `truth_channel`; with `input` (the dynamic
// take the prediction was made from) also the no-removal, low-pass and moving-average
// baselines computed from it (the low-pass with its cutoff by rule, dynamics/baselines.h), and
// "lowpass_oracle": the low-pass at the cutoff of a 0.5..12 Hz sweep that is best against this
// truth — what no user could set, reported so the rule's cost is visible. `rig` may be null (face only). Takes must agree in vertex
// count, frame count and fps; the message says which differs and the two values.
StatusOr<Evaluation> Evaluate(const Take& predicted, const Take& truth, const Take* input,
                              const FaceRig* rig, const EvaluateOptions& options);

// The vertices "where the face jiggles" (issue 4): those whose mean |true dynamic offset| over
// `frames` reaches 20% of the largest vertex's. Without it the forehead and the
// nose bridge, which hardly move against the skull, dilute every relative figure.
std::vector<int> JigglingVertices(const PointCache& true_offsets, dynamics::FrameRange frames);

// Mean |a - b| (mm) over `vertices` and `frames`; both caches in one frame. Preconditions
// (CHECKed, naming both counts): equal vertex and frame counts, vertices and frames in range.
double MeanDistanceOverVertices(const PointCache& a, const PointCache& b,
                                const std::vector<int>& vertices, dynamics::FrameRange frames);

// The removal figure of a simulated take: mean |predicted - exact quasistatic| (mm, world frame)
// over the take's jiggling vertices and its scored frames (dynamics::ScoredFrames with
// `window_frames`). FailedPrecondition when the take lacks its quasistatic or dynamic_offset
// channel, or `predicted` has other vertex or frame counts.
StatusOr<double> JiggleMeanErrorMm(const PointCache& predicted, const Take& simulated,
                                   int window_frames);

// The 95th percentile of `values` (the ceil(0.95 n)-th smallest; 0 when empty).
// How far a fitted expression is from another, as shapes: the RMS over every skin vertex of the
// distance between their upright blendshape skins (mm). Scores an expression fit against the
// simulator's configured expression. Requires one weight per blendshape in both.
double ExpressionSkinRmsMm(const FaceRig& rig, const Eigen::VectorXd& weights,
                           const Eigen::VectorXd& reference);

double Percentile95(std::vector<double> values);

// Fine detail's score (detail/, Masquerade): |result - truth| per vertex and frame, the mean and
// 95th percentile over the whole face and over the `lips` vertices. Frames are 3 x V, one frame;
// CHECKed: equal frame counts and sizes, lips in range.
struct DetailErrors {
  double face_mean_mm = 0, face_p95_mm = 0, lips_mean_mm = 0, lips_p95_mm = 0;
};
DetailErrors ScoreDetail(const std::vector<Eigen::Matrix3Xd>& result,
                         const std::vector<Eigen::Matrix3Xd>& truth, const std::vector<int>& lips);
// {"face_mean_mm", "face_p95_mm", "lips_mean_mm", "lips_p95_mm"}.
Json DetailErrorsJson(const DetailErrors& errors);

// A figure rounded to 1e-4 (0.1 um for mm) for reports: more digits than that are noise.
inline double Round4(double x) { return std::round(x * 1e4) / 1e4; }

// The symmetric range [skip, F - skip) of a take of `frame_count` frames (empty if too short).
inline dynamics::FrameRange EdgeSkipped(int frame_count, int skip) {
  return {skip, std::max(skip, frame_count - skip)};
}

// The positions of the baseline `name` of an Evaluation made with `input` (its reports' names:
// no_removal, lowpass, moving_average, lowpass_oracle at the evaluation's oracle cutoff).
StatusOr<PointCache> BaselinePositions(const Take& input, const Evaluation& evaluation,
                                       const std::string& name,
                                       const dynamics::BaselineOptions& options);

Json EvaluationToJson(const Evaluation& evaluation);
std::string EvaluationToText(const Evaluation& evaluation);

}  // namespace facedyn::eval
