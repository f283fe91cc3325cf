// AravisCamera: a GenICam machine-vision camera through Aravis 0.8 (GigE Vision, USB3
// Vision) — the usual path for 96-128 fps global-shutter cameras.
//
// The camera runs with TriggerMode=On; by default TriggerSource=Software and every trigger of
// the take's trigger source becomes arv_camera_software_trigger(). With `hardware_line` set
// (e.g. "Line0"), the camera is wired to the sync controller and OnTrigger does nothing.
// Frames map to triggers by the GVSP/U3V frame id: the first frame delivered after arming is
// trigger 0 and later ids count on from it (16-bit GigE ids wrap; the wrap is unrolled), so a
// frame the camera or the network lost appears as a gap in the trigger indices. This assumes
// the first trigger produced a frame (Arm waits 100 ms after AcquisitionStart for that); a
// camera that exposes a trigger counter would let the mapping be absolute. Timestamps:
// the buffer's device timestamp, shifted so the first frame lands on trigger 0's time; the
// camera's clock then carries the timing (its drift against the trigger shows up as
// timestamp mismatches, which is what they are for).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "capture/camera.h"

typedef struct _ArvCamera ArvCamera;
typedef struct _ArvStream ArvStream;

namespace facedyn::capture {

class AravisCamera : public Camera {
 public:
  // `device_id`: an Aravis id ("Aravis-Fake-GV01"), a serial or an IP address.
  AravisCamera(int camera_index, std::string name, std::string device_id,
               std::string hardware_line = "");
  ~AravisCamera() override;

  const std::string& name() const override { return name_; }
  std::string backend() const override { return "aravis"; }
  Status Configure(const CameraSettings& settings) override;
  const CameraSettings& settings() const override { return settings_; }
  Status Arm() override;
  Status OnTrigger(const TriggerEvent& trigger) override;
  Status NextFrame(double timeout_s, Frame* frame, bool* got_frame) override;
  Status Disarm() override;

  int64_t incomplete_buffers() const { return incomplete_buffers_; }

 private:
  int camera_index_;
  std::string name_;
  std::string device_id_;
  std::string hardware_line_;
  CameraSettings settings_;
  ArvCamera* camera_ = nullptr;
  ArvStream* stream_ = nullptr;
  size_t payload_bytes_ = 0;
  bool armed_ = false;
  bool disarmed_ = false;
  std::vector<int64_t> trigger_time_ns_;  // by trigger index, from OnTrigger
  int64_t first_frame_id_ = -1;
  int64_t last_frame_id_ = -1;
  int64_t frame_id_base_ = 0;  // unrolled wraps
  int64_t timestamp_offset_ns_ = 0;
  int64_t incomplete_buffers_ = 0;
};

}  // namespace facedyn::capture
