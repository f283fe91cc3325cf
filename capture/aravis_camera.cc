#include "capture/aravis_camera.h"

#include <arv.h>

#include <algorithm>
#include <cstring>

namespace facedyn::capture {
namespace {

// Moves a GError into a Status naming the camera and the step.
Status TakeError(GError** error, const std::string& what) {
  if (*error == nullptr) return Status::Ok();
  std::string message = what + ": " + (*error)->message;
  g_clear_error(error);
  return UnavailableError(message);
}

constexpr int kStreamBuffers = 32;

}  // namespace

AravisCamera::AravisCamera(int camera_index, std::string name, std::string device_id,
                           std::string hardware_line)
    : camera_index_(camera_index),
      name_(std::move(name)),
      device_id_(std::move(device_id)),
      hardware_line_(std::move(hardware_line)) {}

AravisCamera::~AravisCamera() {
  (void)Disarm();
  if (stream_ != nullptr) g_object_unref(stream_);
  if (camera_ != nullptr) g_object_unref(camera_);
}

Status AravisCamera::Configure(const CameraSettings& settings) {
  FACEDYN_RETURN_IF_ERROR(settings.Check());
  if (settings.format != PixelFormat::kMono8 && settings.format != PixelFormat::kMono16) {
    return InvalidArgumentError("camera " + name_ + ": the aravis backend records mono8 or mono16");
  }
  GError* error = nullptr;
  if (camera_ == nullptr) {
    camera_ = arv_camera_new(device_id_.c_str(), &error);
    FACEDYN_RETURN_IF_ERROR(
        TakeError(&error, "camera " + name_ + ": cannot open Aravis device '" + device_id_ + "'"));
    if (camera_ == nullptr)
      return UnavailableError("camera " + name_ + ": no Aravis device '" + device_id_ + "'");
  }
  const std::string what = "camera " + name_ + " (" + device_id_ + ")";
  arv_camera_set_pixel_format(
      camera_,
      settings.format == PixelFormat::kMono8 ? ARV_PIXEL_FORMAT_MONO_8 : ARV_PIXEL_FORMAT_MONO_16,
      &error);
  FACEDYN_RETURN_IF_ERROR(
      TakeError(&error, what + ": PixelFormat " + PixelFormatName(settings.format)));
  arv_camera_set_region(camera_, 0, 0, settings.width_px, settings.height_px, &error);
  FACEDYN_RETURN_IF_ERROR(TakeError(&error, what + ": region " + std::to_string(settings.width_px) +
                                                "x" + std::to_string(settings.height_px)));
  gint x, y, width, height;
  arv_camera_get_region(camera_, &x, &y, &width, &height, &error);
  FACEDYN_RETURN_IF_ERROR(TakeError(&error, what + ": reading the region back"));
  if (width != settings.width_px || height != settings.height_px) {
    return InvalidArgumentError(what + ": asked for " + std::to_string(settings.width_px) + "x" +
                                std::to_string(settings.height_px) + ", the camera set " +
                                std::to_string(width) + "x" + std::to_string(height));
  }
  arv_camera_set_acquisition_mode(camera_, ARV_ACQUISITION_MODE_CONTINUOUS, &error);
  FACEDYN_RETURN_IF_ERROR(TakeError(&error, what + ": AcquisitionMode Continuous"));
  // Some cameras (the fake one too) also pace triggered frames by AcquisitionFrameRate, and
  // start exposures on its grid: run it at its maximum so a trigger is served at once. (Set
  // before the trigger: arv_camera_set_frame_rate turns TriggerMode off.)
  if (arv_camera_is_frame_rate_available(camera_, nullptr)) {
    double min_fps = 0, max_fps = 0;
    arv_camera_get_frame_rate_bounds(camera_, &min_fps, &max_fps, &error);
    g_clear_error(&error);
    if (max_fps > 0) {
      arv_camera_set_frame_rate(camera_, max_fps, &error);
      FACEDYN_RETURN_IF_ERROR(TakeError(&error, what + ": AcquisitionFrameRate"));
    }
  }
  arv_camera_set_trigger(camera_, hardware_line_.empty() ? "Software" : hardware_line_.c_str(),
                         &error);
  FACEDYN_RETURN_IF_ERROR(
      TakeError(&error, what + ": TriggerSource " +
                            (hardware_line_.empty() ? std::string("Software") : hardware_line_)));
  arv_camera_set_exposure_time(camera_, settings.exposure_us, &error);
  FACEDYN_RETURN_IF_ERROR(
      TakeError(&error, what + ": ExposureTime " + std::to_string(settings.exposure_us) + " us"));
  payload_bytes_ = arv_camera_get_payload(camera_, &error);
  FACEDYN_RETURN_IF_ERROR(TakeError(&error, what + ": PayloadSize"));
  settings_ = settings;
  const size_t expected =
      static_cast<size_t>(settings.width_px) * settings.height_px * BytesPerPixel(settings.format);
  if (payload_bytes_ < expected) {
    return FailedPreconditionError(what + ": payload " + std::to_string(payload_bytes_) +
                                   " bytes is smaller than the image");
  }
  return Status::Ok();
}

Status AravisCamera::Arm() {
  if (camera_ == nullptr)
    return FailedPreconditionError("camera " + name_ + ": Arm before Configure");
  GError* error = nullptr;
  stream_ = arv_camera_create_stream(camera_, nullptr, nullptr, &error);
  FACEDYN_RETURN_IF_ERROR(TakeError(&error, "camera " + name_ + ": creating the stream"));
  if (stream_ == nullptr) return UnavailableError("camera " + name_ + ": no stream");
  for (int i = 0; i < kStreamBuffers; ++i)
    arv_stream_push_buffer(stream_, arv_buffer_new(payload_bytes_, nullptr));
  trigger_time_ns_.clear();
  first_frame_id_ = last_frame_id_ = -1;
  frame_id_base_ = 0;
  arv_camera_start_acquisition(camera_, &error);
  FACEDYN_RETURN_IF_ERROR(TakeError(&error, "camera " + name_ + ": AcquisitionStart"));
  // Frames map to triggers from the first frame on, so the first trigger must not arrive before
  // the camera's trigger logic runs: give it a moment after AcquisitionStart.
  g_usleep(100000);
  armed_ = true;
  disarmed_ = false;
  return Status::Ok();
}

Status AravisCamera::OnTrigger(const TriggerEvent& trigger) {
  if (!armed_ || disarmed_)
    return FailedPreconditionError("camera " + name_ + ": trigger while not armed");
  if (static_cast<int64_t>(trigger_time_ns_.size()) <= trigger.index)
    trigger_time_ns_.resize(trigger.index + 1, 0);
  trigger_time_ns_[trigger.index] = trigger.time_ns;
  if (!hardware_line_.empty()) return Status::Ok();
  GError* error = nullptr;
  arv_camera_software_trigger(camera_, &error);
  return TakeError(
      &error, "camera " + name_ + ": TriggerSoftware for trigger " + std::to_string(trigger.index));
}

Status AravisCamera::Disarm() {
  if (!armed_ || disarmed_) return Status::Ok();
  disarmed_ = true;
  GError* error = nullptr;
  arv_camera_stop_acquisition(camera_, &error);
  Status status = TakeError(&error, "camera " + name_ + ": AcquisitionStop");
  return status;
}

Status AravisCamera::NextFrame(double timeout_s, Frame* frame, bool* got_frame) {
  *got_frame = false;
  if (stream_ == nullptr) return AbortedError("camera " + name_ + ": not armed");
  for (;;) {
    // After Disarm, drain what the stream already holds without waiting long.
    const guint64 timeout_us = disarmed_ ? 100000 : static_cast<guint64>(timeout_s * 1e6);
    ArvBuffer* buffer = arv_stream_timeout_pop_buffer(stream_, timeout_us);
    if (buffer == nullptr) {
      if (disarmed_) {
        g_object_unref(stream_);
        stream_ = nullptr;
        armed_ = false;
        return AbortedError("camera " + name_ + ": disarmed");
      }
      return Status::Ok();  // nothing within the timeout
    }
    if (arv_buffer_get_status(buffer) != ARV_BUFFER_STATUS_SUCCESS) {
      ++incomplete_buffers_;  // the frame id then never arrives: a gap the sync checker counts
      arv_stream_push_buffer(stream_, buffer);
      continue;
    }
    const int64_t raw_id = static_cast<int64_t>(arv_buffer_get_frame_id(buffer));
    const int64_t device_ns = static_cast<int64_t>(arv_buffer_get_timestamp(buffer));
    if (first_frame_id_ < 0) {
      first_frame_id_ = raw_id;
      timestamp_offset_ns_ = (trigger_time_ns_.empty() ? 0 : trigger_time_ns_[0]) - device_ns;
    } else if (raw_id < last_frame_id_ && last_frame_id_ - raw_id > 30000) {
      frame_id_base_ += 65535;  // GigE Vision 16-bit block ids wrap (0 is never used)
    }
    last_frame_id_ = raw_id;
    size_t size = 0;
    const void* data = arv_buffer_get_data(buffer, &size);
    frame->camera_index = camera_index_;
    frame->trigger_index = raw_id + frame_id_base_ - first_frame_id_;
    frame->timestamp_ns = device_ns + timestamp_offset_ns_;
    frame->exposure_us = settings_.exposure_us;
    frame->width_px = settings_.width_px;
    frame->height_px = settings_.height_px;
    frame->format = settings_.format;
    frame->pixels.resize(frame->ExpectedBytes());
    if (size < frame->pixels.size()) {
      arv_stream_push_buffer(stream_, buffer);
      return DataLossError("camera " + name_ + ": buffer of " + std::to_string(size) +
                           " bytes for a " + std::to_string(frame->pixels.size()) + "-byte image");
    }
    std::memcpy(frame->pixels.data(), data, frame->pixels.size());
    arv_stream_push_buffer(stream_, buffer);
    *got_frame = true;
    return Status::Ok();
  }
}

}  // namespace facedyn::capture
