// `facedyn view`: one self-contained HTML page to look at takes in a browser (three.js from
// Debian's libjs-three, inlined; nothing is fetched). Takes side by side or overlaid,
// play/pause at the take's fps, a frame slider, an orbit camera, and the skin coloured by
//   - offset: the signed dynamic offset along the skin's normal, red out and green in (Zoss et
//     al.'s convention). The offset is positions minus the take's "quasistatic" channel when
//     it has one (the simulator's exact one, a synthesis output's), else positions minus the
//     80 ms moving average in the skull frame (dynamics/quasistatic.h, Eq. 5): what a viewer
//     can say about a take that carries no quasistatic estimate. The legend names which.
//   - error: the distance to a truth take's positions, per vertex and frame (white to red);
//   - none: skin tone.
// One colour range for every take on the page (the largest 99th percentile of |value|), so
// colours compare across takes; the legend gives it in mm.
//
// Size: per take, frame 0 as float32 plus each frame's offset from it as int16 with a per-take
// step (1/32767 of the largest offset, in the page's data) and one int8 colour value per vertex
// and frame: 7 bytes per vertex per frame, 9.3 once base64 in the page. 35.1 MB for 3 s of a
// 9,409-vertex take at 128 fps, three.js included (`build/bench/export_bench`, 2026-12-04).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/status.h"
#include "core/take.h"

namespace facedyn::report {

enum class ViewerColour { kOffset, kError, kNone };

struct ViewerTake {
  std::string label;  // shown above the take (the folder name, say)
  Take take;
};

struct ViewerOptions {
  ViewerColour colour = ViewerColour::kOffset;
  // kError: the truth every take is compared with (same vertex and frame count).
  std::optional<Take> truth;
  std::string title = "facedyn take viewer";
  // The frames shown: from first_frame, at most max_frames (0: to the end). Colours are
  // computed on the whole take first, so a window does not change them.
  int first_frame = 0;
  int max_frames = 0;
  // three.js r111 and its OrbitControls as Debian's libjs-three installs them.
  std::string three_js_path = "/usr/share/javascript/three/build/three.min.js";
  std::string orbit_controls_path = "/usr/share/javascript/three/examples/js/controls/OrbitControls.js";
};

struct ViewerSummary {
  uint64_t bytes = 0;
  int frames = 0;
  double colour_range_mm = 0.0;
};

// "offset" | "error" | "none", and back (the truth take is given separately).
const char* ViewerColourName(ViewerColour colour);
StatusOr<ViewerColour> ParseViewerColour(const std::string& name);

// Writes the page atomically. Errors: no takes; takes whose frame rates differ; a window that
// holds no frame of some take (first_frame < 0 or past its end, max_frames < 0); a truth take
// (or, for kError, its absence) that does not match a take's vertex or frame count; a missing
// three.js (naming the Debian package); an unwritable path.
StatusOr<ViewerSummary> WriteTakeViewer(const std::vector<ViewerTake>& takes,
                                        const ViewerOptions& options, const std::string& path);

}  // namespace facedyn::report
