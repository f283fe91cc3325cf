#include "sim/drive_sim.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

namespace facedyn::sim {

Status DriveModelOptions::Check() const {
  if (!(accel_hz_per_s > 0.0 && accel_hz_per_s <= 1000.0)) {
    return InvalidArgumentError(fmt::format("model.accel_hz_per_s: {} is outside (0, 1000]", accel_hz_per_s));
  }
  if (!(max_hz > 0.0 && max_hz <= 1000.0)) {
    return InvalidArgumentError(fmt::format("model.max_hz: {} is outside (0, 1000]", max_hz));
  }
  if (!(watchdog_s >= 0.0 && watchdog_s <= 3600.0)) {
    return InvalidArgumentError(fmt::format("model.watchdog_s: {} is outside [0, 3600]", watchdog_s));
  }
  if (watchdog_fault_code < 0 || watchdog_fault_code > 0xFFFF) {
    return InvalidArgumentError(fmt::format("model.watchdog_fault_code: {} is outside 0..65535",
                                            watchdog_fault_code));
  }
  return Status::Ok();
}

void DriveModel::SetSetpointHz(double hz) {
  state_.setpoint_hz = std::clamp(hz, 0.0, options_.max_hz);
}

void DriveModel::Run() {
  // A tripped drive ignores run commands until it is reset, like the real ones.
  if (state_.fault_code == 0) {
    state_.run_commanded = true;
    state_.watchdog_fired = false;
  }
}

void DriveModel::Stop() { state_.run_commanded = false; }

void DriveModel::ResetFault() {
  state_.fault_code = 0;
  state_.run_commanded = false;
}

void DriveModel::ForceFault(int code) {
  state_.fault_code = code;
  state_.run_commanded = false;
}

void DriveModel::Advance(double dt_s) {
  if (dt_s <= 0.0) return;
  silent_s_ += dt_s;
  if (options_.watchdog_s > 0.0 && state_.run_commanded && silent_s_ >= options_.watchdog_s) {
    state_.run_commanded = false;
    state_.watchdog_fired = true;
    if (options_.watchdog_fault_code != 0) state_.fault_code = options_.watchdog_fault_code;
  }
  if (state_.fault_code != 0) {
    state_.output_hz = 0.0;  // a trip removes the output: the motor coasts
    return;
  }
  const double target_hz = state_.run_commanded ? state_.setpoint_hz : 0.0;
  const double step_hz = options_.accel_hz_per_s * dt_s;
  if (state_.output_hz < target_hz) {
    state_.output_hz = std::min(target_hz, state_.output_hz + step_hz);
  } else {
    state_.output_hz = std::max(target_hz, state_.output_hz - step_hz);
  }
}

Status DriveSimOptions::Check() const {
  if (host.empty()) return InvalidArgumentError("sim.host: must not be empty");
  if (port < 0 || port > 65535) return InvalidArgumentError(fmt::format("sim.port: {} is outside 0..65535", port));
  if (!(step_s > 0.0 && step_s <= 1.0)) return InvalidArgumentError(fmt::format("sim.step_s: {} is outside (0, 1]", step_s));
  return model.Check();
}

DriveSim::DriveSim(const rig::DriveProfile& profile, const DriveSimOptions& options)
    : profile_(profile), options_(options), model_(options.model) {}

StatusOr<std::unique_ptr<DriveSim>> DriveSim::Start(const rig::DriveProfile& profile,
                                                     const DriveSimOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<DriveSim> sim(new DriveSim(profile, options));
  FACEDYN_RETURN_IF_ERROR(sim->Listen());
  sim->RefreshRegisters();
  sim->thread_ = std::thread([raw = sim.get()] { raw->Serve(); });
  return sim;
}

Status DriveSim::Listen() {
  ctx_ = modbus_new_tcp(options_.host.c_str(), options_.port);
  if (ctx_ == nullptr) {
    return InvalidArgumentError(fmt::format("simulated drive: cannot create a context for {}:{}: {}",
                                            options_.host, options_.port, modbus_strerror(errno)));
  }
  mapping_ = modbus_mapping_new(0, 0, profile_.MaxRegister() + 1, 0);
  if (mapping_ == nullptr) {
    return InternalError(fmt::format("simulated drive: cannot allocate {} registers: {}",
                                     profile_.MaxRegister() + 1, modbus_strerror(errno)));
  }
  listen_socket_ = modbus_tcp_listen(ctx_, 8);
  if (listen_socket_ == -1) {
    return UnavailableError(fmt::format("simulated drive: cannot listen on {}:{}: {}", options_.host,
                                        options_.port, modbus_strerror(errno)));
  }
  sockaddr_in bound{};
  socklen_t length = sizeof(bound);
  if (getsockname(listen_socket_, reinterpret_cast<sockaddr*>(&bound), &length) != 0) {
    return UnavailableError(fmt::format("simulated drive: getsockname: {}", std::strerror(errno)));
  }
  port_ = ntohs(bound.sin_port);
  return Status::Ok();
}

DriveSim::~DriveSim() {
  stopping_ = true;
  if (thread_.joinable()) thread_.join();
  if (listen_socket_ != -1) ::close(listen_socket_);
  if (mapping_ != nullptr) modbus_mapping_free(mapping_);
  if (ctx_ != nullptr) modbus_free(ctx_);
}

void DriveSim::ForceFault(int code) {
  std::lock_guard<std::mutex> lock(model_mutex_);
  model_.ForceFault(code);
}

DriveModelState DriveSim::state() const {
  std::lock_guard<std::mutex> lock(model_mutex_);
  return model_.state();
}

// Caller holds model_mutex_ (or the thread is not started yet).
void DriveSim::RefreshRegisters() {
  const DriveModelState& s = model_.state();
  uint16_t status = 0;
  if (model_.running()) status |= profile_.running_value & profile_.running_mask;
  if (s.fault_code != 0) status |= profile_.fault_mask;
  uint16_t* registers = mapping_->tab_registers;
  registers[profile_.status_register] = status;
  const auto output = profile_.output_scaling.HzToRegister(s.output_hz, "simulated output");
  registers[profile_.output_frequency_register] = output.ok() ? *output : 0xFFFF;
  if (profile_.fault_code_register) {
    const uint16_t code_bits =
        static_cast<uint16_t>((s.fault_code << profile_.fault_code_shift) & profile_.fault_code_mask);
    uint16_t& word = registers[*profile_.fault_code_register];
    if (*profile_.fault_code_register == profile_.status_register) {
      word = static_cast<uint16_t>((word & ~profile_.fault_code_mask) | code_bits);
    } else {
      word = code_bits;
    }
  }
}

// Caller holds model_mutex_.
void DriveSim::HandleWrite(int function, int address, int count) {
  if (function != MODBUS_FC_WRITE_SINGLE_REGISTER && function != MODBUS_FC_WRITE_MULTIPLE_REGISTERS) {
    return;
  }
  const int register_count = mapping_->nb_registers;
  for (int reg = address; reg < address + count && reg < register_count; ++reg) {
    const uint16_t value = mapping_->tab_registers[reg];
    const bool is_reset = !profile_.fault_reset_values.empty() && value == profile_.fault_reset_values[0];
    if (reg == profile_.fault_reset_register && is_reset) {
      model_.ResetFault();
    } else if (reg == profile_.command_register) {
      if (value == profile_.run_value) model_.Run();
      else if (value == profile_.stop_value) model_.Stop();
    }
    if (reg == profile_.setpoint_register) {
      model_.SetSetpointHz(profile_.setpoint_scaling.RegisterToHz(value));
    }
    if (profile_.comm_watchdog && profile_.comm_watchdog->register_address &&
        reg == *profile_.comm_watchdog->register_address) {
      model_.SetWatchdogS(value / profile_.comm_watchdog->counts_per_s);
    }
  }
}

void DriveSim::Serve() {
  using Clock = std::chrono::steady_clock;
  std::vector<int> clients;
  auto last = Clock::now();
  const int header_length = modbus_get_header_length(ctx_);
  uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
  while (!stopping_) {
    fd_set readable;
    FD_ZERO(&readable);
    FD_SET(listen_socket_, &readable);
    int highest = listen_socket_;
    for (const int fd : clients) {
      FD_SET(fd, &readable);
      highest = std::max(highest, fd);
    }
    timeval timeout{0, static_cast<suseconds_t>(options_.step_s * 1e6)};
    const int ready = select(highest + 1, &readable, nullptr, nullptr, &timeout);
    const auto now = Clock::now();
    {
      std::lock_guard<std::mutex> lock(model_mutex_);
      model_.Advance(std::chrono::duration<double>(now - last).count());
      RefreshRegisters();
    }
    last = now;
    if (ready <= 0) continue;

    if (FD_ISSET(listen_socket_, &readable)) {
      const int fd = ::accept(listen_socket_, nullptr, nullptr);
      if (fd >= 0) clients.push_back(fd);
    }
    for (auto it = clients.begin(); it != clients.end();) {
      const int fd = *it;
      if (!FD_ISSET(fd, &readable)) {
        ++it;
        continue;
      }
      modbus_set_socket(ctx_, fd);
      const int length = modbus_receive(ctx_, query);
      if (length == -1) {  // peer closed or sent garbage: drop the connection
        ::close(fd);
        it = clients.erase(it);
        continue;
      }
      ++it;
      if (length == 0) continue;  // addressed to another unit
      if (drop_requests_ > 0) {
        --drop_requests_;
        ++requests_dropped_;
        continue;  // lost on the wire: neither applied nor answered
      }
      const double delay_s = reply_delay_s_;
      if (delay_s > 0.0) std::this_thread::sleep_for(std::chrono::duration<double>(delay_s));
      std::lock_guard<std::mutex> lock(model_mutex_);
      model_.NoteRequest();
      RefreshRegisters();
      // Replies to reads of status registers carry the refreshed values; writes land in the
      // mapping and are then interpreted.
      if (modbus_reply(ctx_, query, length, mapping_) == -1) {
        spdlog::debug("simulated drive: reply failed: {}", modbus_strerror(errno));
        continue;
      }
      const int function = query[header_length];
      const int address = (query[header_length + 1] << 8) | query[header_length + 2];
      const int count = function == MODBUS_FC_WRITE_MULTIPLE_REGISTERS
                            ? ((query[header_length + 3] << 8) | query[header_length + 4])
                            : 1;
      HandleWrite(function, address, count);
      RefreshRegisters();
      ++requests_served_;
    }
  }
  for (const int fd : clients) ::close(fd);
}

}  // namespace facedyn::sim
