#include "report/take_viewer.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/file_util.h"
#include "core/json_io.h"
#include "core/mesh.h"
#include "core/progress.h"
#include "dynamics/quasistatic.h"
#include "report/face_render.h"
#include "report/report.h"
#include "report/take_viewer_page.h"

namespace facedyn::report {
namespace {

// The moving average's half-window when a take has no quasistatic channel: the paper's 80 ms.
constexpr double kMovingAverageHalfWindowS = 0.08;

template <typename T>
std::string Base64Of(const std::vector<T>& values) {
  std::vector<unsigned char> bytes(values.size() * sizeof(T));
  if (!bytes.empty()) std::memcpy(bytes.data(), values.data(), bytes.size());
  return Base64(bytes);
}

// Per vertex and frame, the value the page colours by (mm), frame-major (F x V).
struct ColourValues {
  std::vector<float> values;
  std::string how;  // what the values are, for the legend
};

StatusOr<ColourValues> OffsetValues(const Take& take) {
  ColourValues out;
  PointCache reference;
  const auto quasistatic = take.channels.find("quasistatic");
  if (quasistatic != take.channels.end()) {
    reference = quasistatic->second;
    out.how = "offset from the take's quasistatic channel";
  } else {
    const int half_window = std::max(1, static_cast<int>(std::lround(kMovingAverageHalfWindowS * take.info.fps)));
    FACEDYN_ASSIGN_OR_RETURN(reference, dynamics::MovingAverageInSkull(take.positions, take.world_from_skull,
                                                                         half_window));
    out.how = "offset from the 80 ms moving average in the skull frame";
  }
  const int frames = take.frame_count(), vertices = take.vertex_count();
  out.values.resize(static_cast<size_t>(frames) * vertices);
  for (int f = 0; f < frames; ++f) {
    const Eigen::Matrix3Xd rest = reference.Frame(f).cast<double>();
    const Eigen::Matrix3Xd normals = VertexNormals(take.topology, rest);
    const Eigen::Matrix3Xd offset = take.FramePositions(f) - rest;
    for (int v = 0; v < vertices; ++v) {
      out.values[static_cast<size_t>(f) * vertices + v] = static_cast<float>(offset.col(v).dot(normals.col(v)));
    }
  }
  return out;
}

ColourValues ErrorValues(const Take& take, const Take& truth) {
  ColourValues out;
  out.how = "distance to the truth take";
  const int frames = take.frame_count(), vertices = take.vertex_count();
  out.values.resize(static_cast<size_t>(frames) * vertices);
  for (int f = 0; f < frames; ++f) {
    const Eigen::Matrix3Xd error = take.FramePositions(f) - truth.FramePositions(f);
    for (int v = 0; v < vertices; ++v) {
      out.values[static_cast<size_t>(f) * vertices + v] = static_cast<float>(error.col(v).norm());
    }
  }
  return out;
}

float Percentile99Abs(const std::vector<float>& values) {
  if (values.empty()) return 0.0f;
  std::vector<float> magnitudes(values.size());
  for (size_t i = 0; i < values.size(); ++i) magnitudes[i] = std::abs(values[i]);
  const size_t k = static_cast<size_t>(0.99 * static_cast<double>(magnitudes.size() - 1));
  std::nth_element(magnitudes.begin(), magnitudes.begin() + static_cast<std::ptrdiff_t>(k), magnitudes.end());
  return magnitudes[k];
}

std::string TakeSummary(const Take& take) {
  std::string text = fmt::format("{} frames at {:g} fps, {} vertices", take.frame_count(), take.info.fps,
                                 take.vertex_count());
  for (const auto& [key, value] :
       {std::pair<const char*, const std::string*>{"subject", &take.info.subject},
        {"expression", &take.info.expression}, {"motion", &take.info.motion}, {"source", &take.info.source}}) {
    if (!value->empty()) text += fmt::format(" · {} {}", key, *value);
  }
  if (take.info.platform_hz) text += fmt::format(" · platform {:g} Hz", *take.info.platform_hz);
  return text;
}

// "</script" must not appear inside an inline script; JSON and base64 never produce it, but
// labels and metadata are user text.
std::string EscapeForScript(const std::string& json) {
  std::string out;
  out.reserve(json.size());
  for (char c : json) {
    if (c == '<') {
      out += "\\u003c";
    } else {
      out += c;
    }
  }
  return out;
}

Status ReplaceOnce(std::string* page, const std::string& marker, const std::string& value) {
  const size_t at = page->find(marker);
  if (at == std::string::npos) return InternalError("viewer page template lacks " + marker);
  page->replace(at, marker.size(), value);
  return Status::Ok();
}

}  // namespace

const char* ViewerColourName(ViewerColour colour) {
  switch (colour) {
    case ViewerColour::kOffset: return "offset";
    case ViewerColour::kError: return "error";
    case ViewerColour::kNone: return "none";
  }
  return "none";
}

StatusOr<ViewerColour> ParseViewerColour(const std::string& name) {
  if (name == "offset") return ViewerColour::kOffset;
  if (name == "error") return ViewerColour::kError;
  if (name == "none") return ViewerColour::kNone;
  return InvalidArgumentError("unknown colour mode '" + name + "' (use offset, error:TRUTH_TAKE or none)");
}

StatusOr<ViewerSummary> WriteTakeViewer(const std::vector<ViewerTake>& takes, const ViewerOptions& options,
                                        const std::string& path) {
  if (takes.empty()) return InvalidArgumentError("view: no takes to show");
  for (const ViewerTake& entry : takes) {
    FACEDYN_RETURN_IF_ERROR(entry.take.Validate());
    if (entry.take.info.fps != takes[0].take.info.fps) {
      return InvalidArgumentError(fmt::format("view: take '{}' is at {:g} fps and '{}' at {:g} fps; one page plays one rate",
                                              entry.label, entry.take.info.fps, takes[0].label, takes[0].take.info.fps));
    }
  }
  if (options.first_frame < 0 || options.max_frames < 0) {
    return InvalidArgumentError(fmt::format("view: first frame {} and frame count {} must not be negative",
                                            options.first_frame, options.max_frames));
  }
  for (const ViewerTake& entry : takes) {
    if (options.first_frame >= entry.take.frame_count()) {
      return InvalidArgumentError(fmt::format("view: take '{}' has {} frames; the first frame shown would be {}",
                                              entry.label, entry.take.frame_count(), options.first_frame));
    }
  }
  if (options.colour == ViewerColour::kError) {
    if (!options.truth) return InvalidArgumentError("view: --color error needs a truth take (error:TRUTH_TAKE)");
    FACEDYN_RETURN_IF_ERROR(options.truth->Validate());
    for (const ViewerTake& entry : takes) {
      if (entry.take.vertex_count() != options.truth->vertex_count() ||
          entry.take.frame_count() != options.truth->frame_count()) {
        return InvalidArgumentError(fmt::format(
            "view: take '{}' has {} vertices and {} frames, the truth take {} and {}: they must match to be compared",
            entry.label, entry.take.vertex_count(), entry.take.frame_count(), options.truth->vertex_count(),
            options.truth->frame_count()));
      }
    }
  }
  auto three = ReadFileToString(options.three_js_path);
  if (!three.ok()) {
    return FailedPreconditionError("view: three.js is not at " + options.three_js_path +
                                   " (Debian package libjs-three; scripts/install-deps.sh installs it)");
  }
  auto orbit = ReadFileToString(options.orbit_controls_path);
  if (!orbit.ok()) {
    return FailedPreconditionError("view: OrbitControls is not at " + options.orbit_controls_path +
                                   " (Debian package libjs-three)");
  }

  // Colour values first: the range is shared by every take on the page.
  std::vector<ColourValues> colours(takes.size());
  float range_mm = 0.0f;
  for (size_t i = 0; i < takes.size(); ++i) {
    const Take& take = takes[i].take;
    if (options.colour == ViewerColour::kOffset) {
      FACEDYN_ASSIGN_OR_RETURN(colours[i], OffsetValues(take));
    } else if (options.colour == ViewerColour::kError) {
      colours[i] = ErrorValues(take, *options.truth);
    } else {
      colours[i].values.assign(static_cast<size_t>(take.frame_count()) * take.vertex_count(), 0.0f);
      colours[i].how = "no colouring";
    }
    range_mm = std::max(range_mm, Percentile99Abs(colours[i].values));
  }
  if (!(range_mm > 0.0f)) range_mm = 1e-3f;  // everything at zero: any range draws white

  Json data = Json::object();
  int frames = 0;
  size_t longest = 0;
  Json take_entries = Json::array();
  Progress progress("view: encode takes", static_cast<long>(takes.size()));
  for (size_t i = 0; i < takes.size(); ++i) {
    const Take& take = takes[i].take;
    // The window [first, first + f_count) of this take's frames.
    const int first = options.first_frame;
    const int available = take.frame_count() - first;
    const int f_count = options.max_frames > 0 ? std::min(options.max_frames, available) : available;
    const int v_count = take.vertex_count();
    if (f_count > frames) {
      frames = f_count;
      longest = i;
    }
    const Eigen::Matrix3Xi triangles = take.topology.Triangles();
    std::vector<uint32_t> indices(static_cast<size_t>(triangles.size()));
    for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
      for (int k = 0; k < 3; ++k) indices[3 * t + k] = static_cast<uint32_t>(triangles(k, t));
    }
    std::vector<float> base(3 * static_cast<size_t>(v_count));
    const auto base_frame = take.positions.Frame(first);
    std::memcpy(base.data(), base_frame.data(), base.size() * sizeof(float));
    // Offsets from the first frame shown, quantised with one step per take.
    float largest = 0.0f;
    for (int f = 0; f < f_count; ++f) {
      largest = std::max(largest, (take.positions.Frame(first + f) - base_frame).cwiseAbs().maxCoeff());
    }
    const double step_mm = largest > 0.0f ? largest / 32767.0 : 1.0;
    std::vector<int16_t> deltas(3 * static_cast<size_t>(v_count) * f_count);
    for (int f = 0; f < f_count; ++f) {
      const auto frame = take.positions.Frame(first + f);
      for (int v = 0; v < v_count; ++v) {
        for (int k = 0; k < 3; ++k) {
          const double q = std::round((frame(k, v) - base_frame(k, v)) / step_mm);
          deltas[(static_cast<size_t>(f) * v_count + v) * 3 + k] =
              static_cast<int16_t>(std::clamp(q, -32767.0, 32767.0));
        }
      }
    }
    std::vector<int8_t> colour(static_cast<size_t>(f_count) * v_count);
    const size_t colour_offset = static_cast<size_t>(first) * v_count;
    for (size_t j = 0; j < colour.size(); ++j) {
      const double unit = std::clamp(colours[i].values[colour_offset + j] / range_mm, -1.0f, 1.0f);
      colour[j] = static_cast<int8_t>(std::lround(unit * 127.0));
    }
    take_entries.push_back({{"label", takes[i].label},
                            {"summary", TakeSummary(take)},
                            {"colour_source", colours[i].how},
                            {"vertices", v_count},
                            {"frames", f_count},
                            {"delta_scale_mm", step_mm},
                            {"triangles", Base64Of(indices)},
                            {"base_mm", Base64Of(base)},
                            {"deltas", Base64Of(deltas)},
                            {"colour", Base64Of(colour)}});
    progress.Advance();
  }
  progress.Finish();
  // Times from the first frame shown, of the take that shows the most frames.
  const Take& timing = takes[longest].take;
  std::vector<double> time_s(frames);
  for (int f = 0; f < frames; ++f) {
    time_s[f] = timing.time_s[options.first_frame + f] - timing.time_s[options.first_frame];
  }
  std::string title = options.colour == ViewerColour::kOffset  ? "signed offset along the normal"
                      : options.colour == ViewerColour::kError ? "distance to the truth"
                                                               : "";
  if (options.colour == ViewerColour::kOffset) {
    bool all_same = true;
    for (const ColourValues& c : colours) all_same = all_same && c.how == colours[0].how;
    title += all_same ? " (" + colours[0].how + ")" : " (per take, see each label)";
  }
  data["takes"] = std::move(take_entries);
  data["frames"] = frames;
  data["first_frame"] = options.first_frame;
  data["fps"] = takes[0].take.info.fps;
  data["time_s"] = time_s;
  data["colour"] = {{"mode", ViewerColourName(options.colour)},
                    {"range_mm", range_mm},
                    {"title", title}};

  std::string page(kTakeViewerPage);
  FACEDYN_RETURN_IF_ERROR(ReplaceOnce(&page, "__FACEDYN_TITLE__", EscapeHtml(options.title)));
  FACEDYN_RETURN_IF_ERROR(ReplaceOnce(&page, "__FACEDYN_THREE_JS__", *three));
  FACEDYN_RETURN_IF_ERROR(ReplaceOnce(&page, "__FACEDYN_ORBIT_CONTROLS_JS__", *orbit));
  FACEDYN_RETURN_IF_ERROR(
      ReplaceOnce(&page, "__FACEDYN_DATA__", EscapeForScript(data.dump(-1, ' ', false, kJsonReplaceInvalidUtf8))));
  FACEDYN_RETURN_IF_ERROR(WriteFileAtomic(path, page));
  ViewerSummary summary;
  summary.bytes = page.size();
  summary.frames = frames;
  summary.colour_range_mm = range_mm;
  return summary;
}

}  // namespace facedyn::report
