// Modbus replies as DriveClient::ReadStatus sees them. Decoding the bytes of a reply (MBAP
// header, function code, byte count, exception replies) happens inside libmodbus, so this
// target runs libmodbus's own client decode on the input — the input is the byte stream a
// "drive" sends back on a socketpair, to the same modbus_read_registers calls ReadStatus's
// transport makes (status word, output frequency, fault code register) — and then fuzzes our
// interpretation of what came out: DecodeDriveStatus on the register values, or the errno
// (EMBX* exception codes, EMBBADDATA, ECONNRESET) on failure. libmodbus itself is the system
// library, not built with coverage or sanitizers, so the fuzzer steers by our code only. The
// first input byte picks the drive profile; the rest is the reply stream.
#include <errno.h>
#include <modbus.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "fuzz/drive_profiles.h"
#include "fuzz/fuzz_util.h"
#include "rig/drive_client.h"
#include "rig/drive_profile.h"

using facedyn::fuzz::ShippedDriveProfiles;

namespace {

// One register read through libmodbus; the reply comes from the stream already in the socket.
std::optional<uint16_t> ReadOne(modbus_t* ctx, int address) {
  uint16_t value = 0;
  const int rc = modbus_read_registers(ctx, address, 1, &value);
  if (rc == 1) return value;
  // What ModbusTransport makes of a failure: the message it puts in the Status.
  const int error = rc == -1 ? errno : EMBBADDATA;
  const std::string message = modbus_strerror(error);
  if (message.empty()) __builtin_trap();
  return std::nullopt;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const auto& profiles = ShippedDriveProfiles();
  const facedyn::rig::DriveProfile& profile = profiles[data[0] % profiles.size()];
  int fds[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM, 0, fds) != 0) std::abort();
  // The whole reply stream is queued, then the "drive" hangs up: a short reply ends in
  // ECONNRESET at once instead of a response timeout.
  size_t written = 0;
  while (written + 1 < size) {
    const ssize_t n = ::write(fds[1], data + 1 + written, size - 1 - written);
    if (n <= 0) std::abort();
    written += static_cast<size_t>(n);
  }
  ::shutdown(fds[1], SHUT_WR);
  modbus_t* ctx = modbus_new_tcp("127.0.0.1", 502);
  if (ctx == nullptr) std::abort();
  modbus_set_socket(ctx, fds[0]);
  modbus_set_response_timeout(ctx, 0, 20000);
  modbus_set_slave(ctx, profile.unit_id);
  const std::optional<uint16_t> status_word = ReadOne(ctx, profile.status_register);
  std::optional<uint16_t> output_word;
  if (status_word) output_word = ReadOne(ctx, profile.output_frequency_register);
  std::optional<uint16_t> fault_word;
  bool complete = status_word && output_word;
  if (complete && profile.fault_code_register &&
      *profile.fault_code_register != profile.status_register) {
    fault_word = ReadOne(ctx, *profile.fault_code_register);
    complete = fault_word.has_value();
  }
  if (complete) {
    const facedyn::rig::DriveStatus status =
        facedyn::rig::DecodeDriveStatus(profile, *status_word, *output_word, fault_word);
    (void)status.ToJson().dump();
  }
  modbus_close(ctx);
  modbus_free(ctx);
  ::close(fds[1]);
  return 0;
}
