// usb_controller_probe: runs a fixed sequence of UsbPlatformController calls and prints one
// JSON object per call, for usb_controller_test to run under umockdev-run (which replaces the
// USB bus of this process only). Stops at the first failure.
//
//   usb_controller_probe [--hz F] [--steps open,set,start,status,accel,trigger,stop,reset]

#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>

#include "core/json_io.h"
#include "rig/usb_controller.h"

namespace {

using facedyn::Json;
using facedyn::Status;

int Report(const std::string& step, const Status& status, Json fields = Json::object()) {
  fields["step"] = step;
  fields["ok"] = status.ok();
  if (!status.ok()) {
    fields["code"] = facedyn::StatusCodeName(status.code());
    fields["error"] = status.message();
  }
  std::printf("%s\n", fields.dump().c_str());
  std::fflush(stdout);
  return status.ok() ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  double hz = 8.5;
  std::string steps = "open,set,start,status,accel,trigger,stop";
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--hz") hz = std::atof(argv[i + 1]);
    if (flag == "--steps") steps = argv[i + 1];
  }
  auto controller = facedyn::rig::UsbPlatformController::Open(facedyn::rig::UsbControllerOptions());
  if (!controller.ok()) return Report("open", controller.status());
  auto& c = **controller;
  std::istringstream list(steps);
  for (std::string step; std::getline(list, step, ',');) {
    int failed = 0;
    if (step == "open") {
      failed = Report(step, Status::Ok(), {{"info", c.info().ToJson()}});
    } else if (step == "set") {
      failed = Report(step, c.SetFrequencyHz(hz));
    } else if (step == "start") {
      failed = Report(step, c.Start());
    } else if (step == "stop") {
      failed = Report(step, c.Stop());
    } else if (step == "reset") {
      failed = Report(step, c.ResetFault());
    } else if (step == "status") {
      auto status = c.ReadStatus();
      failed = Report(step, status.status(),
                      status.ok() ? Json{{"status", status->ToJson()}} : Json::object());
    } else if (step == "accel") {
      auto samples = c.ReadAccelerationG();
      failed = Report(step, samples.status(),
                      samples.ok() ? Json{{"samples_g", *samples}} : Json::object());
    } else if (step == "trigger") {
      failed = Report(step, c.Trigger(128, 1.0 / 128.0));
    } else {
      failed = Report(step, facedyn::InvalidArgumentError("unknown step " + step));
    }
    if (failed) return 1;
  }
  return 0;
}
