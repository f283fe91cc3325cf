#include "reconstruct/session_input.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <opencv2/imgproc.hpp>

#include "capture/frame_file.h"
#include "capture/session.h"
#include "core/json_io.h"
#include "core/progress.h"
#include "reconstruct/calibration.h"

namespace facedyn::reconstruct {
namespace {

// The frame as 8-bit gray (mono16 scaled down, BGR converted).
cv::Mat ToGray(const capture::Frame& frame) {
  cv::Mat gray;
  switch (frame.format) {
    case capture::PixelFormat::kMono8:
      gray = cv::Mat(frame.height_px, frame.width_px, CV_8UC1,
                     const_cast<uint8_t*>(frame.pixels.data()))
                 .clone();
      break;
    case capture::PixelFormat::kMono16: {
      const cv::Mat wide(frame.height_px, frame.width_px, CV_16UC1,
                         const_cast<uint8_t*>(frame.pixels.data()));
      wide.convertTo(gray, CV_8U, 1.0 / 256.0);
      break;
    }
    case capture::PixelFormat::kBgr8: {
      const cv::Mat bgr(frame.height_px, frame.width_px, CV_8UC3,
                        const_cast<uint8_t*>(frame.pixels.data()));
      cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
      break;
    }
  }
  return gray;
}

}  // namespace

Status SessionInputOptions::Check() const {
  return detection.Check().WithContext("marker detection");
}

StatusOr<SessionDetections> DetectSessionTake(const std::string& session_dir,
                                              const std::string& take_name,
                                              const SessionInputOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_ASSIGN_OR_RETURN(const capture::SessionInfo session, capture::ReadSession(session_dir));
  const capture::SessionTake* take = nullptr;
  std::string names;
  for (const auto& t : session.takes) {
    names += (names.empty() ? "" : ", ") + t.name;
    if (t.name == take_name) take = &t;
  }
  if (!take) {
    return NotFoundError("session " + session_dir + " has no take '" + take_name + "'" +
                         (names.empty() ? " (it has no takes)" : " (takes: " + names + ")"));
  }
  const std::string calibration_path =
      options.calibration_path.empty() ? session.calibration_path : options.calibration_path;
  if (calibration_path.empty()) {
    return FailedPreconditionError("session " + session_dir +
                                   " has no calibration; run `facedyn calibrate` and pass "
                                   "--calibration FILE");
  }
  FACEDYN_ASSIGN_OR_RETURN(const RigCalibration calibration, LoadCalibration(calibration_path));
  if (!(take->fps > 0)) {
    return FailedPreconditionError("take " + take_name + " has no frame rate in its manifest (" +
                                   take->status + ")");
  }
  SessionDetections out;
  out.fps = take->fps;
  if (take->manifest.is_object() && take->manifest.contains("platform") &&
      take->manifest["platform"].is_object()) {
    const Json& platform = take->manifest["platform"];
    for (const char* key : {"measured_hz_at_start", "target_hz"}) {
      if (platform.contains(key) && platform[key].is_number() && platform[key].get<double>() > 0) {
        out.platform_hz = platform[key].get<double>();
        break;
      }
    }
  }
  if (take->manifest.is_object() && take->manifest.contains("hold_start_s")) {
    const Json& held = take->manifest["hold_start_s"];
    if (held.is_number() && std::isfinite(held.get<double>()) && held.get<double>() >= 0) {
      out.hold_start_s = held.get<double>();
    } else {
      out.take_problems.push_back("capture.json hold_start_s is " +
                                  held.dump(-1, ' ', false, kJsonReplaceInvalidUtf8) +
                                  ", not a time >= 0 s; every frame counts as held");
    }
  }
  if (take->manifest.is_object() && take->manifest.contains("camera_mount")) {
    const Json& mount = take->manifest["camera_mount"];
    if (mount.is_string() &&
        (mount.get<std::string>() == "head" || mount.get<std::string>() == "world")) {
      out.head_mounted = mount.get<std::string>() == "head";
    } else {
      return FailedPreconditionError("take " + take_name + ": capture.json camera_mount is " +
                                     mount.dump(-1, ' ', false, kJsonReplaceInvalidUtf8) +
                                     ", neither \"world\" nor \"head\"");
    }
  }
  MarkerDetectionOptions detection = options.detection;
  if (out.head_mounted) detection.occlusion_refit = false;  // see session_input.h
  out.take_problems.insert(out.take_problems.end(), take->problems.begin(), take->problems.end());
  std::vector<std::unique_ptr<capture::FrameFileReader>> readers;
  int64_t last_trigger = -1;
  for (const capture::SessionTakeCamera& camera : take->cameras) {
    const auto calibrated = std::find_if(calibration.cameras.begin(), calibration.cameras.end(),
                                         [&](const Camera& c) { return c.name == camera.name; });
    if (calibrated == calibration.cameras.end()) {
      out.take_problems.push_back("camera " + camera.name + " is not in " + calibration_path +
                                  "; left out");
      continue;
    }
    if (!camera.problem.empty()) {
      out.take_problems.push_back("camera " + camera.name + ": " + camera.problem + "; left out");
      continue;
    }
    auto reader = capture::FrameFileReader::Open(camera.frame_file);
    if (!reader.ok()) {
      out.take_problems.push_back("camera " + camera.name + ": " + reader.status().message() +
                                  "; left out");
      continue;
    }
    if (!(*reader)->scan().tail_problem.empty()) {
      out.take_problems.push_back("camera " + camera.name + ": " + (*reader)->scan().tail_problem);
    }
    for (const std::string& problem : (*reader)->scan().record_problems)
      out.take_problems.push_back("camera " + camera.name + ": " + problem);
    for (const auto& record : (*reader)->scan().records) {
      last_trigger = std::max(last_trigger, record.trigger_index);
    }
    out.cameras.push_back(*calibrated);
    readers.push_back(std::move(*reader));
  }
  for (const Camera& c : calibration.cameras) {
    const bool in_take = std::any_of(take->cameras.begin(), take->cameras.end(),
                                     [&](const auto& t) { return t.name == c.name; });
    if (!in_take)
      out.take_problems.push_back("calibrated camera " + c.name + " recorded nothing in this take");
  }
  if (out.cameras.size() < 2) {
    return FailedPreconditionError("take " + take_name + " has " +
                                   std::to_string(out.cameras.size()) +
                                   " usable calibrated cameras; reconstruction needs at least 2");
  }
  const int64_t frame_count = std::max<int64_t>(last_trigger + 1, take->triggers_emitted);
  if (frame_count <= 0) return FailedPreconditionError("take " + take_name + " has no frames");
  out.detections.assign(frame_count,
                        std::vector<std::vector<ImageObservation>>(out.cameras.size()));
  out.frame_problems.assign(frame_count, {});
  const double period_ns = 1e9 / take->fps;
  Progress progress("detect markers", static_cast<long>(frame_count));
  capture::Frame frame;
  for (int64_t t = 0; t < frame_count; ++t) {
    std::vector<cv::Mat> images(out.cameras.size());
    std::vector<int64_t> stamps(out.cameras.size(), INT64_MIN);
    for (size_t c = 0; c < out.cameras.size(); ++c) {
      const int index = readers[c]->FindTrigger(t);
      if (index < 0) {
        out.frame_problems[t].push_back(out.cameras[c].name + ": no frame (dropped)");
        continue;
      }
      const Status read = readers[c]->Read(index, &frame);
      if (!read.ok()) {
        out.frame_problems[t].push_back(out.cameras[c].name + ": " + read.message());
        continue;
      }
      if (frame.width_px != out.cameras[c].width_px ||
          frame.height_px != out.cameras[c].height_px) {
        out.frame_problems[t].push_back(out.cameras[c].name + ": frame is " +
                                        std::to_string(frame.width_px) + "x" +
                                        std::to_string(frame.height_px) + ", calibration says " +
                                        std::to_string(out.cameras[c].width_px) + "x" +
                                        std::to_string(out.cameras[c].height_px));
        continue;
      }
      images[c] = ToGray(frame);
      stamps[c] = frame.timestamp_ns;
    }
    std::vector<int64_t> present;
    for (int64_t s : stamps) {
      if (s != INT64_MIN) present.push_back(s);
    }
    std::sort(present.begin(), present.end());
    const int64_t median = present.empty() ? 0 : present[present.size() / 2];
    const auto start = std::chrono::steady_clock::now();
    for (size_t c = 0; c < out.cameras.size(); ++c) {
      if (images[c].empty()) continue;
      if (std::abs(static_cast<double>(stamps[c] - median)) > 0.5 * period_ns) {
        out.frame_problems[t].push_back(
            out.cameras[c].name + ": out of sync by " +
            std::to_string(static_cast<int>(std::lround((stamps[c] - median) / 1e6))) + " ms");
        images[c] = cv::Mat();
      }
    }
    std::vector<MarkerDetectionSummary> summaries;
    const auto found = DetectMarkersInImages(images, detection, 0, &summaries);
    for (size_t c = 0; c < summaries.size(); ++c) {
      if (images[c].empty()) continue;
      const MarkerDetectionSummary& s = summaries[c];
      MarkerDetectionSummary& total = out.detection_totals;
      ++out.images_detected;
      total.candidates += s.candidates;
      total.accepted += s.accepted;
      total.rejected_fit += s.rejected_fit;
      total.rejected_size += s.rejected_size;
      total.rejected_size_unfitted += s.rejected_size_unfitted;
      total.fits += s.fits;
      total.rejected_contrast += s.rejected_contrast;
      total.rejected_quality += s.rejected_quality;
      total.duplicates += s.duplicates;
      total.fit_iterations += s.fit_iterations;
      total.fit_evaluations += s.fit_evaluations;
      total.fit_pixel_evaluations += s.fit_pixel_evaluations;
      total.occlusion_fits += s.occlusion_fits;
      total.occlusion_iterations += s.occlusion_iterations;
      total.refitted_for_occlusion += s.refitted_for_occlusion;
      total.candidates_ms += s.candidates_ms;
      total.fit_ms += s.fit_ms;
      total.occlusion_ms += s.occlusion_ms;
    }
    for (size_t c = 0; c < out.cameras.size(); ++c) {
      if (images[c].empty()) continue;
      if (!found[c].ok()) {
        out.frame_problems[t].push_back(out.cameras[c].name + ": " + found[c].status().message());
        continue;
      }
      for (const MarkerDetection& d : *found[c]) {
        ImageObservation o;
        o.camera = static_cast<int>(c);
        o.detection = static_cast<int>(out.detections[t][c].size());
        o.pixel = d.center_px;
        o.weight = d.quality;
        out.detections[t][c].push_back(o);
      }
    }
    out.detect_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    progress.Advance();
  }
  progress.Finish();
  return out;
}

}  // namespace facedyn::reconstruct
