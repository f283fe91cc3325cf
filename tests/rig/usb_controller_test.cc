// UsbPlatformController against a scripted USB device: umockdev-run gives the probe program
// (usb_controller_probe.cc) a fake USB bus holding tests/rig/usb_controller.umockdev (bus 1,
// device 3, 1209:0001) and replays a usbmon capture that this test writes: for each control
// transfer, the submit the client must send (setup packet compared byte for byte) and the
// device's completion (status, reply bytes). A request that differs from the script is never
// answered, so the client's encoding of the vendor protocol is checked, not just its decoding.
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/rig/rig_test_util.h"

namespace facedyn {
namespace {

using ::testing::HasSubstr;

constexpr const char* kSysfsPath = "/sys/devices/pci0000:00/0000:00:14.0/usb1/1-2";

bool UmockdevAvailable() {
  std::string output;
  return testing::RunCommand("command -v umockdev-run", &output) == 0;
}

#define FACEDYN_REQUIRE_UMOCKDEV()                                            \
  if (!UmockdevAvailable()) {                                                 \
    if (testing::InCi()) FAIL() << "umockdev is missing and CI=true";         \
    GTEST_SKIP() << "umockdev not installed (needed to script a USB device)"; \
  }

// A pcap file of LINKTYPE_USB_LINUX_MMAPPED (220) records, as Wireshark saves from usbmon.
class UsbCapture {
 public:
  // A vendor IN request answered with `reply` (status 0), or failed with `status` (-EPIPE: stall).
  void In(uint8_t request, uint16_t length, const std::vector<uint8_t>& reply, int status = 0) {
    const auto setup = Setup(0xC0, request, 0, 0, length);
    Record(++urb_, 'S', 0x80, 0, '<', -EINPROGRESS, length, {}, setup);
    Record(urb_, 'C', 0x80, '-', status == 0 ? 0 : '<', status, status == 0 ? reply.size() : 0,
           status == 0 ? reply : std::vector<uint8_t>(), {});
  }
  void Out(uint8_t request, uint16_t value, uint16_t index, int status = 0) {
    const auto setup = Setup(0x40, request, value, index, 0);
    Record(++urb_, 'S', 0x00, 0, '>', -EINPROGRESS, 0, {}, setup);
    Record(urb_, 'C', 0x00, '-', '>', status, 0, {}, {});
  }
  void Write(const std::string& path) const {
    std::ofstream out(path, std::ios::binary);
    const uint32_t header[] = {0xa1b2c3d4, 0x00040002, 0, 0, 65535, 220};
    out.write(reinterpret_cast<const char*>(header), sizeof(header));
    out.write(reinterpret_cast<const char*>(bytes_.data()),
              static_cast<std::streamsize>(bytes_.size()));
  }

 private:
  static std::vector<uint8_t> Setup(uint8_t type, uint8_t request, uint16_t value, uint16_t index,
                                    uint16_t length) {
    return {type,
            request,
            uint8_t(value & 0xFF),
            uint8_t(value >> 8),
            uint8_t(index & 0xFF),
            uint8_t(index >> 8),
            uint8_t(length & 0xFF),
            uint8_t(length >> 8)};
  }
  template <typename T>
  static void Put(std::vector<uint8_t>* out, T value) {
    const auto* p = reinterpret_cast<const uint8_t*>(&value);
    out->insert(out->end(), p, p + sizeof(T));
  }
  // The 64-byte usbmon "mmapped" header (linux/Documentation/usb/usbmon.rst), then the data.
  void Record(uint64_t id, char event, uint8_t endpoint, char setup_flag, char data_flag,
              int32_t status, uint32_t urb_len, const std::vector<uint8_t>& data,
              const std::vector<uint8_t>& setup) {
    time_us_ += 1000;
    std::vector<uint8_t> packet;
    Put<uint64_t>(&packet, id);
    Put<uint8_t>(&packet, static_cast<uint8_t>(event));
    Put<uint8_t>(&packet, 2);  // control transfer
    Put<uint8_t>(&packet, endpoint);
    Put<uint8_t>(&packet, 3);   // device address
    Put<uint16_t>(&packet, 1);  // bus
    Put<uint8_t>(&packet, static_cast<uint8_t>(setup_flag));
    Put<uint8_t>(&packet, static_cast<uint8_t>(data_flag));
    Put<int64_t>(&packet, 0);
    Put<int32_t>(&packet, static_cast<int32_t>(time_us_));
    Put<int32_t>(&packet, status);
    Put<uint32_t>(&packet, urb_len);
    Put<uint32_t>(&packet, static_cast<uint32_t>(data.size()));
    std::vector<uint8_t> s = setup;
    s.resize(8, 0);
    packet.insert(packet.end(), s.begin(), s.end());
    for (int i = 0; i < 4; ++i)
      Put<int32_t>(&packet, 0);  // interval, start_frame, xfer_flags, ndesc
    packet.insert(packet.end(), data.begin(), data.end());
    Put<uint32_t>(&bytes_, 0);
    Put<uint32_t>(&bytes_, static_cast<uint32_t>(time_us_));
    Put<uint32_t>(&bytes_, static_cast<uint32_t>(packet.size()));
    Put<uint32_t>(&bytes_, static_cast<uint32_t>(packet.size()));
    bytes_.insert(bytes_.end(), packet.begin(), packet.end());
  }

  std::vector<uint8_t> bytes_;
  uint64_t urb_ = 0xffff888000000000ull;
  uint32_t time_us_ = 0;
};

std::vector<uint8_t> Le(std::initializer_list<int> u8_then_u16) {
  // First two values are bytes, the rest 16-bit little-endian words.
  std::vector<uint8_t> out;
  int i = 0;
  for (int v : u8_then_u16) {
    if (i++ < 2) {
      out.push_back(static_cast<uint8_t>(v));
    } else {
      out.push_back(static_cast<uint8_t>(v & 0xFF));
      out.push_back(static_cast<uint8_t>((v >> 8) & 0xFF));
    }
  }
  return out;
}

std::vector<uint8_t> Info(int version = 1) { return Le({version, 0x07, 500, 1200, 3}); }

std::string ProbePath() { return std::string(FACEDYN_PROBE_PATH); }

// Runs the probe on the scripted device; returns its JSON lines.
std::vector<nlohmann::json> RunProbe(const testing::TempDir& dir, const UsbCapture& capture,
                                     const std::string& args, int* exit_code,
                                     const std::string& device_file = "") {
  capture.Write(dir.Join("session.pcap"));
  const std::string device =
      device_file.empty() ? testing::RigTestScript("usb_controller.umockdev") : device_file;
  std::string output;
  *exit_code = testing::RunCommand(
      fmt::format("timeout 30 umockdev-run -d {} -p {}={} -- {} {} 2>/dev/null", device, kSysfsPath,
                  dir.Join("session.pcap"), ProbePath(), args),
      &output);
  std::vector<nlohmann::json> lines;
  size_t begin = 0;
  while (begin < output.size()) {
    const size_t end = output.find('\n', begin);
    const std::string line =
        output.substr(begin, end == std::string::npos ? std::string::npos : end - begin);
    begin = end == std::string::npos ? output.size() : end + 1;
    if (!line.empty() && line[0] == '{') lines.push_back(nlohmann::json::parse(line));
  }
  EXPECT_FALSE(lines.empty()) << output;
  return lines;
}

TEST(UsbPlatformController, FullSessionAgainstTheScriptedDevice) {
  FACEDYN_REQUIRE_UMOCKDEV();
  testing::TempDir dir;
  UsbCapture capture;
  capture.In(0x01, 8, Info());
  capture.Out(0x10, 850, 0);  // SET_FREQUENCY 8.50 Hz
  capture.Out(0x11, 0, 0);    // START
  capture.In(0x13, 8, Le({0x01, 0, 850, 847, 41}));
  std::vector<uint8_t> accel = {3, 0};  // count 3, then 1000, -500, 12 milli-g
  for (int v : {1000, -500, 12}) {
    accel.push_back(static_cast<uint8_t>(v & 0xFF));
    accel.push_back(static_cast<uint8_t>((v >> 8) & 0xFF));
  }
  capture.In(0x20, 64, accel);
  capture.Out(0x30, 128, 7813);  // TRIGGER 128 pulses at 1/128 s
  capture.Out(0x12, 0, 0);       // STOP
  int code = -1;
  const auto lines = RunProbe(dir, capture, "--hz 8.5", &code);
  ASSERT_EQ(code, 0) << lines.back().dump();
  ASSERT_EQ(lines.size(), 7u);
  EXPECT_EQ(lines[0]["info"]["protocol_version"], 1);
  EXPECT_EQ(lines[0]["info"]["accelerometer_rate_hz"], 500);
  EXPECT_EQ(lines[0]["info"]["max_hz"], 12.0);
  EXPECT_TRUE(lines[0]["info"]["has_trigger"].get<bool>());
  EXPECT_TRUE(lines[3]["status"]["running"].get<bool>());
  EXPECT_NEAR(lines[3]["status"]["measured_hz"].get<double>(), 8.47, 1e-9);
  EXPECT_EQ(lines[3]["status"]["sequence"], 41);
  EXPECT_EQ(lines[4]["samples_g"], nlohmann::json::array({1.0, -0.5, 0.012}));
  for (const auto& line : lines) EXPECT_TRUE(line["ok"].get<bool>()) << line.dump();
}

TEST(UsbPlatformController, ARequestOtherThanTheScriptIsNeverAnswered) {
  FACEDYN_REQUIRE_UMOCKDEV();
  testing::TempDir dir;
  UsbCapture capture;
  capture.In(0x01, 8, Info());
  capture.Out(0x10, 900, 0);  // the device expects 9.00 Hz ...
  int code = -1;
  const auto lines =
      RunProbe(dir, capture, "--hz 8.5 --steps set", &code);  // ... the client sends 8.50
  ASSERT_EQ(code, 1);
  EXPECT_EQ(lines.back()["step"], "set");
  EXPECT_THAT(lines.back()["error"].get<std::string>(), HasSubstr("SET_FREQUENCY"));
  EXPECT_THAT(lines.back()["error"].get<std::string>(), HasSubstr("LIBUSB_ERROR_TIMEOUT"));
}

TEST(UsbPlatformController, StallMeansUnsupportedAndShortRepliesAreDataLoss) {
  FACEDYN_REQUIRE_UMOCKDEV();
  {
    testing::TempDir dir;
    UsbCapture capture;
    capture.In(0x01, 8, Info());
    capture.Out(0x30, 128, 7813, -EPIPE);
    int code = -1;
    const auto lines = RunProbe(dir, capture, "--steps trigger", &code);
    ASSERT_EQ(code, 1);
    EXPECT_EQ(lines.back()["code"], "failed precondition");
    EXPECT_THAT(lines.back()["error"].get<std::string>(),
                HasSubstr("TRIGGER: not supported by the controller's firmware"));
  }
  {
    testing::TempDir dir;
    UsbCapture capture;
    capture.In(0x01, 8, Info());
    capture.In(0x13, 8, {0x01, 0, 0x52, 0x03, 0x4F});  // 5 of 8 bytes
    int code = -1;
    const auto lines = RunProbe(dir, capture, "--steps status", &code);
    ASSERT_EQ(code, 1);
    EXPECT_EQ(lines.back()["code"], "data loss");
    EXPECT_THAT(lines.back()["error"].get<std::string>(), HasSubstr("GET_STATUS: 5 of 8 bytes"));
  }
}

TEST(UsbPlatformController, OtherProtocolVersionIsRefused) {
  FACEDYN_REQUIRE_UMOCKDEV();
  testing::TempDir dir;
  UsbCapture capture;
  capture.In(0x01, 8, Info(/*version=*/2));
  int code = -1;
  const auto lines = RunProbe(dir, capture, "--steps open", &code);
  ASSERT_EQ(code, 1);
  EXPECT_EQ(lines.back()["step"], "open");
  EXPECT_THAT(lines.back()["error"].get<std::string>(),
              HasSubstr("protocol version 2, facedyn speaks 1"));
}

TEST(UsbPlatformController, NoDeviceFoundNamesTheIdAndWhatWasSeen) {
  FACEDYN_REQUIRE_UMOCKDEV();
  testing::TempDir dir;
  // The same bus position holding some other device (a different product id).
  std::string other = testing::ReadBytes(testing::RigTestScript("usb_controller.umockdev"));
  other.replace(other.find("A: idProduct=0001"), 17, "A: idProduct=00ff");
  other.replace(other.find("4009120100"), 10, "400912ff00");
  testing::WriteBytes(dir.Join("other.umockdev"), other);
  UsbCapture capture;
  int code = -1;
  const auto lines = RunProbe(dir, capture, "--steps open", &code, dir.Join("other.umockdev"));
  ASSERT_EQ(code, 1);
  EXPECT_EQ(lines.back()["code"], "not found");
  EXPECT_THAT(lines.back()["error"].get<std::string>(),
              HasSubstr("no USB platform controller 1209:0001 found (1 USB device(s) present)"));
}

TEST(RigUsbStatusCommand, PrintsTheControllerOrSaysNoneWasFound) {
  FACEDYN_REQUIRE_UMOCKDEV();
  testing::TempDir dir;
  UsbCapture capture;
  capture.In(0x01, 8, Info());
  capture.In(0x13, 8, Le({0x02, 7, 1000, 0, 9}));  // faulted, code 7
  capture.Write(dir.Join("session.pcap"));
  std::string output;
  const int code = testing::RunCommand(
      fmt::format("timeout 60 umockdev-run -d {} -p {}={} -- {} rig usb-status --json 2>/dev/null",
                  testing::RigTestScript("usb_controller.umockdev"), kSysfsPath,
                  dir.Join("session.pcap"), testing::FacedynExecutable()),
      &output);
  ASSERT_EQ(code, 0) << output;
  const auto json = nlohmann::json::parse(output.substr(output.find('{')));
  EXPECT_EQ(json["device"], "1209:0001");
  EXPECT_TRUE(json["status"]["faulted"].get<bool>());
  EXPECT_EQ(json["status"]["fault_code"], 7);
  EXPECT_NEAR(json["status"]["setpoint_hz"].get<double>(), 10.0, 1e-9);

  // Asking for another id on the same bus: exit 1 and the no-device message.
  const int missing = testing::RunCommand(
      fmt::format("timeout 60 umockdev-run -d {} -- {} rig usb-status --pid 00aa",
                  testing::RigTestScript("usb_controller.umockdev"), testing::FacedynExecutable()),
      &output);
  EXPECT_EQ(missing, 1) << output;
  EXPECT_THAT(output,
              HasSubstr("no USB platform controller 1209:00aa found (1 USB device(s) present)"));
}

}  // namespace
}  // namespace facedyn
