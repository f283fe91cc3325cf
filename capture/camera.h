// Camera: the interface every acquisition backend implements (simulated, OpenCV VideoCapture,
// Aravis/GenICam), shaped around trigger-synchronised acquisition.
//
// Life cycle: Configure (image size, pixel format, exposure) -> Arm (start the stream, wait
// for triggers) -> per trigger, OnTrigger() is called by the trigger source and frames are
// pulled with NextFrame() from the camera's acquisition thread -> Disarm. The split between
// OnTrigger and NextFrame is what lets one trigger source serve every backend: a simulated
// camera queues the trigger and renders it in NextFrame (so N cameras render on N threads); a
// software-triggered camera (Aravis TriggerSource=Software, an OpenCV grab) fires its trigger;
// a camera on a hardware trigger line ignores the call. Every frame carries the trigger index
// it was exposed by and its timestamp on the session clock; detecting missing or repeated
// indices is the FrameSyncChecker's job (capture/frame_sync.h), not the backend's.
#pragma once

#include <cstdint>
#include <string>

#include "capture/frame.h"
#include "core/status.h"

namespace facedyn::capture {

struct CameraSettings {
  int width_px = 0;
  int height_px = 0;
  PixelFormat format = PixelFormat::kMono8;
  int exposure_us = 2000;
  double fps = 128.0;  // trigger rate the camera must sustain

  Status Check() const;  // names the field
};

// One trigger pulse: its index since the take armed and its time on the session clock.
struct TriggerEvent {
  int64_t index = 0;
  int64_t time_ns = 0;
};

class Camera {
 public:
  virtual ~Camera() = default;

  virtual const std::string& name() const = 0;
  // "sim", "opencv", "aravis".
  virtual std::string backend() const = 0;

  // Applies the settings; an error names the setting the device refused.
  virtual Status Configure(const CameraSettings& settings) = 0;
  virtual const CameraSettings& settings() const = 0;
  // Starts acquisition; frames are produced from the next trigger on.
  virtual Status Arm() = 0;
  // Called from the trigger thread for every trigger, in index order. Must not block for long
  // (a bounded wait is allowed for simulated cameras, whose clock is virtual).
  virtual Status OnTrigger(const TriggerEvent& trigger) = 0;
  // The next acquired frame into *frame (its pixel buffer is reused), waiting at most
  // `timeout_s`. OK with *got_frame = true: a frame; OK with *got_frame = false: nothing within
  // the timeout (not an error); Aborted: disarmed and drained, no more frames; any other
  // status: the device failed (the take stops and the message is logged).
  virtual Status NextFrame(double timeout_s, Frame* frame, bool* got_frame) = 0;
  // Stops acquisition. Frames already acquired remain available to NextFrame. Idempotent.
  virtual Status Disarm() = 0;
};

}  // namespace facedyn::capture
