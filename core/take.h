// Take: a mesh sequence in fixed topology plus the skull's rigid motion — the currency
// between capture, reconstruction, dynamics and simulation (ARCHITECTURE.md, "Take").
//
// On disk a Take is a folder:
//   take.json       fps, frame_count, vertex_count, units "mm", subject, expression, motion,
//                   platform_hz, source, channels, metadata (free-form object)
//   topology.obj    rest mesh with UVs and faces (defines the vertex order)
//   positions.pc2   per-frame vertex positions in the world frame, mm
//   skull.csv       frame,time_s,qw,qx,qy,qz,tx,ty,tz  (world_from_skull, mm)
//   jaw.csv         optional, same columns, skull_from_jaw
//   <channel>.pc2   optional extra per-frame positions (e.g. quasistatic, dynamic_offset)
// LoadTake validates every cross-file invariant (counts agree, numbers finite, quaternions
// unit, frames numbered in order, time increasing) and names the file and frame or vertex
// of the first violation. SaveTake writes each file atomically and take.json last, so a
// folder with a take.json is complete.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/mesh.h"
#include "core/pc2.h"
#include "core/rigid3.h"
#include "core/status.h"

namespace facedyn {

inline constexpr int kTakeFormatVersion = 1;

// The margin (s) a held-expression take allows the skin's transient after the expression and
// the head motion reach their held values, before a held-expression target is trusted. It is
// one fixed figure, not derived from the tissue: a capture session does not know the actor's
// tissue, so neither may the simulator's take metadata (the true fundamental and damping are
// scoring-only). 0.25 s is three decay times 1/(zeta 2 pi f0) of any tissue with
// f0 * zeta >= 1.91 Hz; the shipped simulated tissue (11 Hz, zeta 0.22) needs 0.197 s.
inline constexpr double kHeldExpressionSettleS = 0.25;

struct TakeInfo {
  double fps = 0.0;
  std::string subject;
  std::string expression;
  std::string motion;    // platform | walk | run | jump | none | captured ...
  std::string source;    // what produced the take: "sim", "reconstruct", "dynamics remove", ...
  std::optional<double> platform_hz;  // platform oscillation frequency, when there was one
  // Time (s, from the first frame) from which the expression is held and the head motion is
  // steady, so a held-expression target (the moving average, the platform-synchronous fit)
  // holds: the simulator writes its expression and motion fade-ins plus
  // kHeldExpressionSettleS. Absent: no such time is known (a performance, or a capture that
  // records after its sweep step settled and the actor was prompted: every frame counts as
  // held).
  std::optional<double> hold_start_s;
  Json metadata = Json::object();
};

struct Take {
  TakeInfo info;
  Mesh topology;
  PointCache positions;                 // world frame, mm
  std::vector<double> time_s;           // per frame, session clock
  std::vector<Rigid3> world_from_skull;  // per frame
  std::vector<Rigid3> skull_from_jaw;    // per frame, or empty
  std::map<std::string, PointCache> channels;

  int frame_count() const { return positions.frame_count(); }
  int vertex_count() const { return topology.vertex_count(); }
  double duration_s() const { return info.fps > 0 ? frame_count() / info.fps : 0.0; }

  // Positions of frame f as doubles (3 x V).
  Eigen::Matrix3Xd FramePositions(int f) const { return positions.Frame(f).cast<double>(); }

  // Sets time_s[f] = f / fps for every frame.
  void SetUniformTimes();

  // Checks the in-memory invariants LoadTake checks on disk.
  Status Validate() const;
};

// First frame of the held part: ceil(hold_start_s * fps) (with 1e-9 of slack for rounding), 0
// without hold_start_s, at most frame_count.
int FirstHeldFrame(const Take& take);

// Channel names are file stems: lower-case letters, digits and '_', not "positions".
bool IsValidChannelName(const std::string& name);

StatusOr<Take> LoadTake(const std::string& dir);
// Creates `dir` if needed. Validates first; writes nothing when the take is inconsistent.
Status SaveTake(const Take& take, const std::string& dir);

// Per-frame rigid transforms as CSV (frame,time_s,qw,qx,qy,qz,tx,ty,tz).
Status WriteTransformCsv(const std::string& path, const std::vector<double>& time_s,
                         const std::vector<Rigid3>& transforms);
// Reads such a CSV; fills time_s and transforms. Errors name file, line and frame.
Status ReadTransformCsv(const std::string& path, std::vector<double>* time_s,
                        std::vector<Rigid3>* transforms);

}  // namespace facedyn
