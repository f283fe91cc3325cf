// OpenCvCamera: a Camera on cv::VideoCapture — V4L2 devices ("/dev/video0" or "0"), video
// files (replay of recorded footage) and GStreamer pipelines (any source containing '!').
//
// VideoCapture has no trigger input, so each trigger grabs one frame (a software trigger): the
// frame carries the trigger's index; its timestamp is the trigger time plus the measured grab
// latency for live sources, and the frame's own media time (CAP_PROP_POS_MSEC) for files, so a
// file whose frame rate differs from the trigger shows up as timestamp mismatches. When a
// file ends before the take, the remaining triggers get no frame (the sync checker counts
// them missing). Colour sources are converted to the configured format (mono8 or bgr8).
#pragma once

#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <opencv2/videoio.hpp>
#include <string>

#include "capture/camera.h"

namespace facedyn::capture {

class OpenCvCamera : public Camera {
 public:
  OpenCvCamera(int camera_index, std::string name, std::string source);

  const std::string& name() const override { return name_; }
  std::string backend() const override { return "opencv"; }
  // Opens the source; for devices asks for the size and rate; a source whose frames are not
  // width x height is an error naming both sizes.
  Status Configure(const CameraSettings& settings) override;
  const CameraSettings& settings() const override { return settings_; }
  Status Arm() override;
  Status OnTrigger(const TriggerEvent& trigger) override;
  Status NextFrame(double timeout_s, Frame* frame, bool* got_frame) override;
  Status Disarm() override;

  bool is_file() const { return is_file_; }
  int64_t exhausted_triggers() const { return exhausted_triggers_; }

 private:
  struct Pending {
    TriggerEvent trigger;
    std::chrono::steady_clock::time_point received;
  };
  int camera_index_;
  std::string name_;
  std::string source_;
  bool is_file_ = false;
  CameraSettings settings_;
  cv::VideoCapture capture_;
  cv::Mat image_, converted_;
  bool configured_ = false;
  bool armed_ = false;
  double first_media_ms_ = -1.0;
  int64_t exhausted_triggers_ = 0;

  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<Pending> pending_;
  bool disarmed_ = false;
};

}  // namespace facedyn::capture
