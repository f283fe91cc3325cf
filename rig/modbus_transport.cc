#include "rig/modbus_transport.h"

#include <fmt/format.h>
#include <modbus.h>
#include <spdlog/spdlog.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <functional>
#include <future>
#include <mutex>
#include <thread>

namespace facedyn::rig {
namespace {

using Clock = std::chrono::steady_clock;

bool IsLinkError(int error) {
  return error == EBADF || error == ECONNRESET || error == EPIPE || error == ECONNREFUSED ||
         error == ENOTCONN || error == ECONNABORTED || error == EIO;
}

// Modbus exception replies: the drive answered. Most are final (illegal function, address,
// value; device failure): retrying gets the same answer. Two say "not now": 05 acknowledge
// (accepted, still processing) and 06 server device busy (Modbus Application Protocol v1.1b3,
// section 7), which the specification asks the client to retry later.
bool IsExceptionReply(int error) { return error >= EMBXILFUN && error <= EMBXGTAR; }
bool IsRetryLaterException(int error) { return error == EMBXACK || error == EMBXSBUSY; }
// Busy replies retried per request (20, 40, ... ms apart: 1.1 s in all) before it fails.
constexpr int kMaxBusyRetries = 10;

}  // namespace

Status TransportOptions::Check() const {
  if (kind == Kind::kTcp) {
    if (host.empty()) return InvalidArgumentError("transport.host: must not be empty");
    if (port < 0 || port > 65535) {
      return InvalidArgumentError(fmt::format("transport.port: {} is outside 0..65535", port));
    }
  } else {
    if (device.empty()) return InvalidArgumentError("transport.device: must name a serial device");
    if (baud <= 0)
      return InvalidArgumentError(fmt::format("transport.baud: {} must be positive", baud));
    if (parity != 'N' && parity != 'E' && parity != 'O') {
      return InvalidArgumentError(fmt::format("transport.parity: '{}' is not N, E or O", parity));
    }
    if (data_bits < 5 || data_bits > 8) {
      return InvalidArgumentError(
          fmt::format("transport.data_bits: {} is outside 5..8", data_bits));
    }
    if (stop_bits != 1 && stop_bits != 2) {
      return InvalidArgumentError(fmt::format("transport.stop_bits: {} is not 1 or 2", stop_bits));
    }
    if (!(rtu_gap_s >= 0.0 && rtu_gap_s <= 1.0)) {
      return InvalidArgumentError(
          fmt::format("transport.rtu_gap_s: {} is outside 0..1 s", rtu_gap_s));
    }
  }
  if (unit_id < 0 || unit_id > 247) {
    return InvalidArgumentError(fmt::format("transport.unit_id: {} is outside 0..247", unit_id));
  }
  if (!(response_timeout_s > 0.0 && response_timeout_s <= 60.0)) {
    return InvalidArgumentError(
        fmt::format("transport.response_timeout_s: {} is outside (0, 60] s", response_timeout_s));
  }
  if (retries < 0 || retries > 20) {
    return InvalidArgumentError(fmt::format("transport.retries: {} is outside 0..20", retries));
  }
  if (healthy_after < 1) {
    return InvalidArgumentError(
        fmt::format("transport.healthy_after: {} must be at least 1", healthy_after));
  }
  return Status::Ok();
}

std::string TransportOptions::Describe() const {
  if (kind == Kind::kTcp) return fmt::format("tcp {}:{}", host, port);
  return fmt::format("rtu {} {} {}{}{}", device, baud, data_bits, parity, stop_bits);
}

Status ParseTcpEndpoint(const std::string& text, TransportOptions* options) {
  const size_t colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == text.size()) {
    return InvalidArgumentError(fmt::format("--tcp: '{}' is not HOST:PORT", text));
  }
  const std::string port_text = text.substr(colon + 1);
  char* end = nullptr;
  const long port = std::strtol(port_text.c_str(), &end, 10);
  if (*end != '\0' || port < 0 || port > 65535) {
    return InvalidArgumentError(
        fmt::format("--tcp: port '{}' is not a number in 0..65535", port_text));
  }
  options->kind = TransportOptions::Kind::kTcp;
  options->host = text.substr(0, colon);
  options->port = static_cast<int>(port);
  return Status::Ok();
}

// The owner thread and everything only it may touch (the modbus_t).
class ModbusTransport::Owner {
 public:
  explicit Owner(const TransportOptions& options) : options_(options) {
    thread_ = std::thread([this] { Run(); });
  }
  ~Owner() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    thread_.join();
  }

  // Runs `job` on the owner thread and returns its status.
  Status Post(std::function<Status(Owner&)> job) {
    auto task = std::make_shared<std::packaged_task<Status()>>([this, job] { return job(*this); });
    std::future<Status> done = task->get_future();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      queue_.push_back([task] { (*task)(); });
    }
    wake_.notify_one();
    return done.get();
  }

  // Owner thread only: connects if needed.
  Status EnsureConnected() {
    if (connected_) return Status::Ok();
    if (ctx_ == nullptr) {
      if (options_.kind == TransportOptions::Kind::kTcp) {
        ctx_ = modbus_new_tcp(options_.host.c_str(), options_.port);
      } else {
        ctx_ = modbus_new_rtu(options_.device.c_str(), options_.baud, options_.parity,
                              options_.data_bits, options_.stop_bits);
      }
      if (ctx_ == nullptr) {
        return InvalidArgumentError(fmt::format("{}: cannot create a Modbus context: {}",
                                                options_.Describe(), modbus_strerror(errno)));
      }
      modbus_set_slave(ctx_, options_.unit_id);
      const double whole_s = std::floor(options_.response_timeout_s);
      modbus_set_response_timeout(
          ctx_, static_cast<uint32_t>(whole_s),
          static_cast<uint32_t>((options_.response_timeout_s - whole_s) * 1e6));
    }
    if (modbus_connect(ctx_) == -1) {
      return UnavailableError(
          fmt::format("{}: cannot connect: {}", options_.Describe(), modbus_strerror(errno)));
    }
    connected_ = true;
    return Status::Ok();
  }

  // Owner thread only: runs one Modbus call with retries. `call` returns libmodbus' rc.
  Status Transact(const std::string& what, const std::function<int(modbus_t*)>& call) {
    std::string last_error;
    int busy_attempts = 0;
    bool after_busy = false;
    for (int attempt = 0; attempt <= options_.retries; ++attempt) {
      if (attempt > 0 && !after_busy) {
        Count([](TransportStats& s) { ++s.retries; });
        spdlog::warn("{}: {}: retry {}/{} after: {}", options_.Describe(), what, attempt,
                     options_.retries, last_error);
      }
      after_busy = false;
      Status connected = EnsureConnected();
      if (!connected.ok()) {
        last_error = connected.message();
        continue;
      }
      WaitRtuGap();
      // RTU frames carry no transaction id: a reply that arrived after an earlier attempt
      // timed out would be taken for this request's answer. Drop anything already received.
      if (options_.kind == TransportOptions::Kind::kRtu) modbus_flush(ctx_);
      const int rc = call(ctx_);
      const int error = errno;
      last_end_ = Clock::now();
      if (rc != -1) {
        Count([](TransportStats& s) {
          ++s.transactions;
          ++s.consecutive_good;
        });
        return Status::Ok();
      }
      last_error = modbus_strerror(error);
      if (IsRetryLaterException(error)) {
        // The drive is alive and asks for a later retry: wait a little (its reply came at
        // once, so without a pause every attempt would land in the same busy window).
        ++busy_attempts;
        if (busy_attempts <= kMaxBusyRetries) {
          after_busy = true;
          --attempt;  // a busy reply is not a link failure and does not use up a retry
          std::this_thread::sleep_for(std::chrono::milliseconds(20) * busy_attempts);
          Count([](TransportStats& s) { ++s.retries; });
          continue;
        }
        Fail();
        return FailedPreconditionError(fmt::format(
            "{}: {}: the drive stayed busy after {} retries: {}", options_.Describe(), what,
            kMaxBusyRetries, last_error));
      }
      if (IsExceptionReply(error)) {
        Fail();
        return FailedPreconditionError(
            fmt::format("{}: {}: the drive refused: {}", options_.Describe(), what, last_error));
      }
      if (IsLinkError(error)) {
        modbus_close(ctx_);
        connected_ = false;
        Count([](TransportStats& s) { ++s.reconnects; });
      } else {
        // Timeout or a corrupt reply: drop whatever half-frame is still in flight so the next
        // attempt does not read a stale answer.
        modbus_flush(ctx_);
      }
    }
    Fail();
    return UnavailableError(fmt::format("{}: {}: failed after {} attempt(s): {}",
                                        options_.Describe(), what, options_.retries + 1,
                                        last_error));
  }

  TransportStats stats() const {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    return stats_;
  }
  bool healthy() const {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    return stats_.consecutive_good >= options_.healthy_after;
  }

 private:
  void Count(const std::function<void(TransportStats&)>& update) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    update(stats_);
  }
  void Fail() {
    Count([](TransportStats& s) {
      ++s.failures;
      s.consecutive_good = 0;
    });
  }

  void WaitRtuGap() {
    if (options_.kind != TransportOptions::Kind::kRtu || last_end_ == Clock::time_point()) return;
    const auto ready = last_end_ + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(options_.rtu_gap_s));
    std::this_thread::sleep_until(ready);
  }

  void Run() {
    for (;;) {
      std::function<void()> job;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        wake_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
        if (queue_.empty()) break;  // stopping and drained
        job = std::move(queue_.front());
        queue_.pop_front();
      }
      job();
    }
    if (ctx_ != nullptr) {
      if (connected_) modbus_close(ctx_);
      modbus_free(ctx_);
      ctx_ = nullptr;
    }
  }

  const TransportOptions options_;
  modbus_t* ctx_ = nullptr;  // owner thread only
  bool connected_ = false;   // owner thread only
  Clock::time_point last_end_;
  mutable std::mutex stats_mutex_;  // guards stats_ against readers on other threads
  TransportStats stats_;

  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::function<void()>> queue_;
  bool stopping_ = false;
  std::thread thread_;
};

ModbusTransport::ModbusTransport(const TransportOptions& options)
    : options_(options), owner_(std::make_unique<Owner>(options)) {}

ModbusTransport::~ModbusTransport() = default;

StatusOr<std::unique_ptr<ModbusTransport>> ModbusTransport::Open(const TransportOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<ModbusTransport> transport(new ModbusTransport(options));
  FACEDYN_RETURN_IF_ERROR(
      transport->owner_->Post([](Owner& owner) { return owner.EnsureConnected(); }));
  return transport;
}

Status ModbusTransport::WriteRegister(int address, uint16_t value) {
  return owner_->Post([address, value](Owner& owner) {
    return owner.Transact(
        fmt::format("write register {} (0x{:04X}) = {}", address, address, value),
        [&](modbus_t* ctx) { return modbus_write_register(ctx, address, value); });
  });
}

Status ModbusTransport::WriteRegisters(int address, const std::vector<uint16_t>& values) {
  return owner_->Post([address, &values](Owner& owner) {
    return owner.Transact(
        fmt::format("write {} registers from {} (0x{:04X})", values.size(), address, address),
        [&](modbus_t* ctx) {
          return modbus_write_registers(ctx, address, static_cast<int>(values.size()),
                                        values.data());
        });
  });
}

StatusOr<std::vector<uint16_t>> ModbusTransport::ReadRegisters(int address, int count) {
  FACEDYN_CHECK(count > 0 && count <= MODBUS_MAX_READ_REGISTERS, "bad register count");
  std::vector<uint16_t> values(static_cast<size_t>(count));
  FACEDYN_RETURN_IF_ERROR(owner_->Post([address, count, &values](Owner& owner) {
    return owner.Transact(
        fmt::format("read {} register(s) from {} (0x{:04X})", count, address, address),
        [&](modbus_t* ctx) {
          const int rc = modbus_read_registers(ctx, address, count, values.data());
          if (rc != -1 && rc != count) {
            errno = EMBBADDATA;
            return -1;
          }
          return rc;
        });
  }));
  return values;
}

bool ModbusTransport::healthy() const { return owner_->healthy(); }

TransportStats ModbusTransport::stats() const { return owner_->stats(); }

}  // namespace facedyn::rig
