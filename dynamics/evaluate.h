// Evaluation of a quasistatic estimate against a truth take: per-vertex Euclidean error
// |y_pred(t) - y_true(t)| (mm) at every frame, summarised as mean, 95th percentile and max over
// the whole face and over each FaceRig region, with the same figures for each baseline
// (baselines.h) computed from the dynamic input. The truth is normally the simulator's exact
// "quasistatic" channel (sim/performance.h), which lets facedyn measure what Zoss et al. 2020
// could only estimate (their Fig. 5 reports average error).
//
// The first and last `skip_edge_frames` frames are left out (default: the feature window,
// round(0.08 s * fps)), where every windowed method runs on replicated edge frames.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/json_io.h"
#include "core/pc2.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/baselines.h"

namespace facedyn::dynamics {

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
  int skip_edge_frames = -1;  // frames left out at each end; -1: round(window_s * fps)
  double window_s = 0.08;     // default skip, and the moving-average baseline's window
  BaselineOptions baselines;
  // truth_channel non-empty, skip_edge_frames >= -1, window_s in [0, 1], baselines valid.
  Status Check() const;
};

// Errors of one point cache against another over frames [skip, F - skip). Errors name what
// differs (vertex count, frame count), a FaceRig of another vertex count, or too few frames.
StatusOr<ErrorReport> ComparePositions(const PointCache& predicted, const PointCache& truth,
                                       const FaceRig* rig, int skip_edge_frames,
                                       const std::string& name);

struct Evaluation {
  std::string truth_channel;
  int frame_count = 0;
  int vertex_count = 0;
  int skip_edge_frames = 0;
  std::vector<ErrorReport> reports;  // the prediction first, then each baseline
};

// The prediction's positions against the truth's `truth_channel`; with `input` (the dynamic
// take the prediction was made from) also the no-removal, low-pass and moving-average
// baselines computed from it. `rig` may be null (face only). Takes must agree in vertex
// count, frame count and fps; the message says which differs and the two values.
StatusOr<Evaluation> Evaluate(const Take& predicted, const Take& truth, const Take* input,
                              const FaceRig* rig, const EvaluateOptions& options);

// The vertices "where the face jiggles" (issue 4): those whose mean |true dynamic offset| over
// frames [skip, F - skip) reaches 20% of the largest vertex's. Without it the forehead and the
// nose bridge, which hardly move against the skull, dilute every relative figure.
std::vector<int> JigglingVertices(const PointCache& true_offsets, int skip);

// Mean |a - b| (mm) over `vertices` and frames [skip, F - skip); both caches in one frame.
double MeanDistanceOverVertices(const PointCache& a, const PointCache& b,
                                const std::vector<int>& vertices, int skip);

Json EvaluationToJson(const Evaluation& evaluation);
std::string EvaluationToText(const Evaluation& evaluation);

}  // namespace facedyn::dynamics
