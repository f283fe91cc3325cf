// ModbusTransport: Modbus TCP or RTU through libmodbus, owned by one thread.
//
// A libmodbus context is not thread-safe, and a drive link is shared by the control loop,
// telemetry and the safety supervisor. So each transport starts one owner thread that creates,
// connects, uses and frees its context; callers on any thread post requests to its queue and
// block on the answer. On the owner thread each request gets a bounded number of attempts:
// a timeout or a corrupt reply (bad CRC/data) flushes the link and retries; a dead socket
// (EBADF, ECONNRESET, EPIPE, ECONNREFUSED, ...) closes and reconnects before the next attempt;
// a Modbus exception reply is the drive's answer and is returned at once, except 05
// (acknowledge) and 06 (server busy), which mean "retry later" and are retried with a backoff. On RTU the thread
// keeps a minimum gap between requests, since many drives need silence after a reply, and
// discards received bytes before each request, since RTU has no transaction id to tell a late
// reply to an earlier attempt from the answer to this one.
//
// The link is "healthy" only after `healthy_after` consecutive good transactions, so one lucky
// reply after a cable fault does not mark it good; any failure resets the count.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/status.h"

namespace facedyn::rig {

struct TransportOptions {
  enum class Kind { kTcp, kRtu };
  Kind kind = Kind::kTcp;
  // TCP
  std::string host = "127.0.0.1";
  int port = 502;
  // RTU
  std::string device;  // e.g. /dev/ttyUSB0
  int baud = 19200;
  char parity = 'N';  // 'N', 'E' or 'O'
  int data_bits = 8;
  int stop_bits = 1;
  double rtu_gap_s = 0.005;  // silence kept between the end of one transaction and the next

  int unit_id = 1;
  double response_timeout_s = 0.5;
  int retries = 2;        // extra attempts after the first
  int healthy_after = 3;  // consecutive good transactions before healthy() is true

  // Names the first invalid field.
  Status Check() const;
  // "tcp 127.0.0.1:5020" or "rtu /dev/ttyUSB0 19200 8N1", for messages.
  std::string Describe() const;
};

// Parses "HOST:PORT" (e.g. "127.0.0.1:5020") into TCP options.
Status ParseTcpEndpoint(const std::string& text, TransportOptions* options);

struct TransportStats {
  long transactions = 0;  // requests answered successfully
  long failures = 0;      // requests that failed after all attempts
  long retries = 0;       // extra attempts made
  long reconnects = 0;    // times the link was closed and reopened
  int consecutive_good = 0;
};

class ModbusTransport {
 public:
  // Starts the owner thread and connects; an unreachable peer is an Unavailable status.
  static StatusOr<std::unique_ptr<ModbusTransport>> Open(const TransportOptions& options);
  ~ModbusTransport();  // stops the thread after the queued requests
  ModbusTransport(const ModbusTransport&) = delete;
  ModbusTransport& operator=(const ModbusTransport&) = delete;

  // Function code 06 (write single register).
  Status WriteRegister(int address, uint16_t value);
  // Function code 16 (write multiple registers).
  Status WriteRegisters(int address, const std::vector<uint16_t>& values);
  // Function code 03 (read holding registers).
  StatusOr<std::vector<uint16_t>> ReadRegisters(int address, int count);

  bool healthy() const;
  TransportStats stats() const;
  const TransportOptions& options() const { return options_; }

 private:
  class Owner;
  explicit ModbusTransport(const TransportOptions& options);

  TransportOptions options_;
  std::unique_ptr<Owner> owner_;
};

}  // namespace facedyn::rig
