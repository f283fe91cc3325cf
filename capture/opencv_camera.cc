#include "capture/opencv_camera.h"

#include <spdlog/spdlog.h>

#include <cctype>
#include <cstring>
#include <filesystem>
#include <opencv2/imgproc.hpp>

namespace facedyn::capture {

OpenCvCamera::OpenCvCamera(int camera_index, std::string name, std::string source)
    : camera_index_(camera_index), name_(std::move(name)), source_(std::move(source)) {}

Status OpenCvCamera::Configure(const CameraSettings& settings) {
  FACEDYN_RETURN_IF_ERROR(settings.Check());
  if (settings.format == PixelFormat::kMono16)
    return InvalidArgumentError("camera " + name_ + ": the opencv backend records mono8 or bgr8");
  const bool all_digits =
      !source_.empty() && std::all_of(source_.begin(), source_.end(), [](char c) {
        return std::isdigit(static_cast<unsigned char>(c));
      });
  const bool pipeline = source_.find('!') != std::string::npos;
  const bool device = all_digits || source_.rfind("/dev/video", 0) == 0;
  is_file_ = !pipeline && !device;
  try {
    if (all_digits) {
      capture_.open(std::stoi(source_), cv::CAP_V4L2);
    } else if (pipeline) {
      capture_.open(source_, cv::CAP_GSTREAMER);
    } else if (device) {
      capture_.open(source_, cv::CAP_V4L2);
    } else {
      if (!std::filesystem::is_regular_file(source_))
        return NotFoundError("camera " + name_ + ": video file " + source_ + " not found");
      capture_.open(source_, cv::CAP_ANY);
    }
  } catch (const cv::Exception& e) {
    return UnavailableError("camera " + name_ + ": cannot open " + source_ + ": " + e.what());
  }
  if (!capture_.isOpened())
    return UnavailableError("camera " + name_ + ": OpenCV cannot open source '" + source_ + "'");
  if (device) {
    capture_.set(cv::CAP_PROP_FRAME_WIDTH, settings.width_px);
    capture_.set(cv::CAP_PROP_FRAME_HEIGHT, settings.height_px);
    capture_.set(cv::CAP_PROP_FPS, settings.fps);
  }
  const int width = static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_WIDTH));
  const int height = static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_HEIGHT));
  // A GStreamer pipeline reports 0x0 until its first buffer: its size is checked frame by frame.
  const bool size_unknown = pipeline && width == 0 && height == 0;
  if (!size_unknown && (width != settings.width_px || height != settings.height_px)) {
    return InvalidArgumentError("camera " + name_ + ": source " + source_ + " delivers " +
                                std::to_string(width) + "x" + std::to_string(height) +
                                ", the take wants " + std::to_string(settings.width_px) + "x" +
                                std::to_string(settings.height_px));
  }
  if (device && !capture_.set(cv::CAP_PROP_EXPOSURE, settings.exposure_us / 100.0)) {
    spdlog::warn(
        "camera {}: the source does not accept an exposure setting; it runs on its own exposure",
        name_);
  }
  settings_ = settings;
  configured_ = true;
  return Status::Ok();
}

Status OpenCvCamera::Arm() {
  if (!configured_) return FailedPreconditionError("camera " + name_ + ": Arm before Configure");
  std::lock_guard<std::mutex> lock(mutex_);
  pending_.clear();
  disarmed_ = false;
  armed_ = true;
  return Status::Ok();
}

Status OpenCvCamera::OnTrigger(const TriggerEvent& trigger) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!armed_) return FailedPreconditionError("camera " + name_ + ": trigger while not armed");
  if (disarmed_) return Status::Ok();
  pending_.push_back({trigger, std::chrono::steady_clock::now()});
  changed_.notify_all();
  return Status::Ok();
}

Status OpenCvCamera::Disarm() {
  std::lock_guard<std::mutex> lock(mutex_);
  disarmed_ = true;
  changed_.notify_all();
  return Status::Ok();
}

Status OpenCvCamera::NextFrame(double timeout_s, Frame* frame, bool* got_frame) {
  *got_frame = false;
  for (;;) {
    Pending pending;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                        [&] { return !pending_.empty() || disarmed_; });
      if (pending_.empty()) {
        if (disarmed_) return AbortedError("camera " + name_ + ": disarmed");
        return Status::Ok();  // no trigger within the timeout
      }
      pending = pending_.front();
      pending_.pop_front();
    }
    bool ok = false;
    try {
      ok = capture_.read(image_);
    } catch (const cv::Exception& e) {
      return UnavailableError("camera " + name_ + ": read failed: " + e.what());
    }
    if (!ok || image_.empty()) {
      if (exhausted_triggers_++ == 0)
        spdlog::warn("camera {}: source {} has no more frames", name_, source_);
      continue;  // this trigger gets no frame: the sync checker counts it missing
    }
    const auto grabbed = std::chrono::steady_clock::now();
    if (settings_.format == PixelFormat::kMono8) {
      if (image_.channels() == 3)
        cv::cvtColor(image_, converted_, cv::COLOR_BGR2GRAY);
      else if (image_.channels() == 4)
        cv::cvtColor(image_, converted_, cv::COLOR_BGRA2GRAY);
      else
        converted_ = image_;
    } else {
      if (image_.channels() == 1)
        cv::cvtColor(image_, converted_, cv::COLOR_GRAY2BGR);
      else
        converted_ = image_;
    }
    if (converted_.depth() != CV_8U || converted_.cols != settings_.width_px ||
        converted_.rows != settings_.height_px) {
      return DataLossError("camera " + name_ + ": frame of " + std::to_string(converted_.cols) +
                           "x" + std::to_string(converted_.rows) + " (depth " +
                           std::to_string(converted_.depth()) + ") from " + source_);
    }
    frame->camera_index = camera_index_;
    frame->trigger_index = pending.trigger.index;
    frame->exposure_us = settings_.exposure_us;
    frame->width_px = settings_.width_px;
    frame->height_px = settings_.height_px;
    frame->format = settings_.format;
    if (is_file_) {
      const double media_ms = capture_.get(cv::CAP_PROP_POS_MSEC);
      if (first_media_ms_ < 0) first_media_ms_ = media_ms;
      frame->timestamp_ns = static_cast<int64_t>((media_ms - first_media_ms_) * 1e6);
    } else {
      frame->timestamp_ns =
          pending.trigger.time_ns +
          std::chrono::duration_cast<std::chrono::nanoseconds>(grabbed - pending.received).count();
    }
    frame->pixels.resize(frame->ExpectedBytes());
    const size_t row_bytes =
        static_cast<size_t>(settings_.width_px) * BytesPerPixel(settings_.format);
    for (int y = 0; y < settings_.height_px; ++y)
      std::memcpy(frame->pixels.data() + y * row_bytes, converted_.ptr(y), row_bytes);
    *got_frame = true;
    return Status::Ok();
  }
}

}  // namespace facedyn::capture
