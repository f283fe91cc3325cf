#include "sim/drive_sim.h"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <netinet/in.h>
#include <spdlog/spdlog.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <vector>

#include "rig/rig_config.h"

namespace facedyn::sim {

using Clock = std::chrono::steady_clock;

Status DriveModelOptions::Check() const {
  if (!(accel_hz_per_s > 0.0 && accel_hz_per_s <= 1000.0)) {
    return InvalidArgumentError(
        fmt::format("model.accel_hz_per_s: {} is outside (0, 1000]", accel_hz_per_s));
  }
  if (!(max_hz > 0.0 && max_hz <= 1000.0)) {
    return InvalidArgumentError(fmt::format("model.max_hz: {} is outside (0, 1000]", max_hz));
  }
  if (!(watchdog_s >= 0.0 && watchdog_s <= 3600.0)) {
    return InvalidArgumentError(
        fmt::format("model.watchdog_s: {} is outside [0, 3600]", watchdog_s));
  }
  if (watchdog_fault_code < 0 || watchdog_fault_code > 0xFFFF) {
    return InvalidArgumentError(
        fmt::format("model.watchdog_fault_code: {} is outside 0..65535", watchdog_fault_code));
  }
  if (!(platform_ratio > 0.0 && platform_ratio <= 100.0)) {
    return InvalidArgumentError(
        fmt::format("model.platform_ratio: {} is outside (0, 100]", platform_ratio));
  }
  if (!(slip_base >= 0.0 && slip_load >= 0.0 && slip_base + slip_load < 0.5)) {
    return InvalidArgumentError(
        fmt::format("model.slip_base/slip_load: {} + {} must be non-negative and below 0.5",
                    slip_base, slip_load));
  }
  if (!(slip_reference_hz > 0.0)) {
    return InvalidArgumentError(
        fmt::format("model.slip_reference_hz: {} must be positive", slip_reference_hz));
  }
  if (!(sensor_window_s >= 0.01 && sensor_window_s <= 10.0)) {
    return InvalidArgumentError(
        fmt::format("model.sensor_window_s: {} is outside [0.01, 10] s", sensor_window_s));
  }
  if (!(sensor_noise_hz >= 0.0 && sensor_noise_hz <= 1.0)) {
    return InvalidArgumentError(
        fmt::format("model.sensor_noise_hz: {} is outside [0, 1]", sensor_noise_hz));
  }
  if (!(sensor_gain >= 0.5 && sensor_gain <= 1.5)) {
    return InvalidArgumentError(
        fmt::format("model.sensor_gain: {} is outside [0.5, 1.5]", sensor_gain));
  }
  return Status::Ok();
}

Status ParseDriveModelOptions(const ConfigNode& node, DriveModelOptions* options) {
  if (!node.IsMap()) return node.Error("expected a map");
  struct Field {
    const char* key;
    double* value;
    double min, max;
  };
  const Field fields[] = {
      {"accel_hz_per_s", &options->accel_hz_per_s, 0.01, 1000.0},
      {"max_hz", &options->max_hz, 0.1, 1000.0},
      {"platform_ratio", &options->platform_ratio, 1e-3, 100.0},
      {"slip_base", &options->slip_base, 0.0, 0.49},
      {"slip_load", &options->slip_load, 0.0, 0.49},
      {"slip_reference_hz", &options->slip_reference_hz, 0.1, 1000.0},
      {"sensor_window_s", &options->sensor_window_s, 0.01, 10.0},
      {"sensor_noise_hz", &options->sensor_noise_hz, 0.0, 1.0},
      {"sensor_gain", &options->sensor_gain, 0.5, 1.5},
  };
  for (const std::string& key : node.Keys()) {
    bool known = key == "watchdog_fault_code" || key == "seed";
    for (const Field& field : fields) known = known || key == field.key;
    if (!known) {
      return node.Error(key,
                        "unknown field (expected accel_hz_per_s, max_hz, watchdog_fault_code, "
                        "platform_ratio, slip_base, slip_load, slip_reference_hz, "
                        "sensor_window_s, sensor_noise_hz, sensor_gain or seed)");
    }
  }
  for (const Field& field : fields) {
    if (!node.Has(field.key)) continue;
    FACEDYN_ASSIGN_OR_RETURN(*field.value, node.GetInRange(field.key, field.min, field.max));
  }
  if (node.Has("watchdog_fault_code")) {
    FACEDYN_ASSIGN_OR_RETURN(options->watchdog_fault_code, node.Get<int>("watchdog_fault_code"));
  }
  if (node.Has("seed")) {
    FACEDYN_ASSIGN_OR_RETURN(const int seed, node.Get<int>("seed"));
    options->seed = static_cast<uint64_t>(seed);
  }
  const Status valid = options->Check();
  if (!valid.ok()) return node.Error(valid.message());
  return Status::Ok();
}

Status LoadDriveSimFromRig(const std::string& rig_path, rig::DriveProfile* profile,
                           DriveSimOptions* options) {
  FACEDYN_ASSIGN_OR_RETURN(const rig::RigConfig config, rig::LoadRigConfig(rig_path));
  *profile = config.profile;
  if (config.transport.kind == rig::TransportOptions::Kind::kTcp) {
    options->rtu_device.clear();
    options->host = config.transport.host;
    options->port = config.transport.port;
  } else {
    options->rtu_device = config.transport.device;
    options->baud = config.transport.baud;
    options->parity = config.transport.parity;
    options->data_bits = config.transport.data_bits;
    options->stop_bits = config.transport.stop_bits;
  }
  FACEDYN_ASSIGN_OR_RETURN(const ConfigNode root, ConfigNode::ReadFile(rig_path));
  if (root.Has("sim")) {
    FACEDYN_ASSIGN_OR_RETURN(const ConfigNode section, root.Child("sim"));
    FACEDYN_RETURN_IF_ERROR(ParseDriveModelOptions(section, &options->model));
  }
  return Status::Ok();
}

DriveModel::DriveModel(const DriveModelOptions& options)
    : options_(options), random_(options.seed) {}

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

void DriveModel::ScheduleTrip(double after_s, int code) {
  trip_after_s_ = after_s;
  trip_code_ = code;
}

double DriveModel::SlipAt(double output_hz) const {
  const double load = output_hz / options_.slip_reference_hz;
  return options_.slip_base + options_.slip_load * load * load;
}

void DriveModel::Advance(double dt_s) {
  if (dt_s <= 0.0) return;
  state_.time_s += dt_s;
  silent_s_ += dt_s;
  if (options_.watchdog_s > 0.0 && state_.run_commanded && silent_s_ >= options_.watchdog_s) {
    state_.run_commanded = false;
    state_.watchdog_fired = true;
    if (options_.watchdog_fault_code != 0) state_.fault_code = options_.watchdog_fault_code;
  }
  if (trip_after_s_ >= 0.0 && running()) {
    trip_after_s_ -= dt_s;
    if (trip_after_s_ < 0.0) ForceFault(trip_code_);
  }
  if (state_.fault_code != 0) {
    state_.output_hz = 0.0;  // a trip removes the output: the motor coasts (modelled as instant)
  } else {
    const double target_hz = state_.run_commanded ? state_.setpoint_hz : 0.0;
    const double step_hz = options_.accel_hz_per_s * dt_s;
    if (state_.output_hz < target_hz) {
      state_.output_hz = std::min(target_hz, state_.output_hz + step_hz);
    } else {
      state_.output_hz = std::max(target_hz, state_.output_hz - step_hz);
    }
  }
  state_.platform_hz =
      state_.output_hz * options_.platform_ratio * (1.0 - SlipAt(state_.output_hz));
  phase_cycles_ += state_.platform_hz * dt_s;
  phase_history_.emplace_back(state_.time_s, phase_cycles_);
  while (phase_history_.size() > 2 &&
         phase_history_[1].first <= state_.time_s - options_.sensor_window_s) {
    phase_history_.pop_front();
  }
  const auto& [then_s, then_cycles] = phase_history_.front();
  const double span_s = state_.time_s - then_s;
  const double mean_hz = span_s > 0.0 ? (phase_cycles_ - then_cycles) / span_s : 0.0;
  const double noisy_hz = options_.sensor_gain * mean_hz + options_.sensor_noise_hz * noise_(random_);
  state_.sensor_hz = state_.platform_hz == 0.0 && mean_hz == 0.0 ? 0.0 : std::max(0.0, noisy_hz);
}

Status DriveSimOptions::Check() const {
  if (is_rtu()) {
    if (baud <= 0) return InvalidArgumentError(fmt::format("sim.baud: {} must be positive", baud));
    if (parity != 'N' && parity != 'E' && parity != 'O') {
      return InvalidArgumentError(fmt::format("sim.parity: '{}' is not N, E or O", parity));
    }
    if (data_bits < 5 || data_bits > 8) {
      return InvalidArgumentError(fmt::format("sim.data_bits: {} is outside 5..8", data_bits));
    }
    if (stop_bits != 1 && stop_bits != 2) {
      return InvalidArgumentError(fmt::format("sim.stop_bits: {} is not 1 or 2", stop_bits));
    }
  } else {
    if (host.empty()) return InvalidArgumentError("sim.host: must not be empty");
    if (port < 0 || port > 65535) {
      return InvalidArgumentError(fmt::format("sim.port: {} is outside 0..65535", port));
    }
  }
  if (!(step_s > 0.0 && step_s <= 1.0)) {
    return InvalidArgumentError(fmt::format("sim.step_s: {} is outside (0, 1]", step_s));
  }
  return model.Check();
}

DriveSim::DriveSim(const rig::DriveProfile& profile, const DriveSimOptions& options)
    : profile_(profile), options_(options), model_(options.model) {}

std::optional<DriveWrite> DecodeAcceptedWrite(const uint8_t* pdu, int length,
                                              int register_count) {
  if (pdu == nullptr || length < 5) return std::nullopt;
  DriveWrite write;
  write.function = pdu[0];
  write.address = (pdu[1] << 8) | pdu[2];
  if (write.function == MODBUS_FC_WRITE_SINGLE_REGISTER) {
    if (write.address >= register_count) return std::nullopt;
    write.values.push_back(static_cast<uint16_t>((pdu[3] << 8) | pdu[4]));
    return write;
  }
  if (write.function != MODBUS_FC_WRITE_MULTIPLE_REGISTERS || length < 6) return std::nullopt;
  const int quantity = (pdu[3] << 8) | pdu[4];
  const int byte_count = pdu[5];
  if (quantity < 1 || quantity > MODBUS_MAX_WRITE_REGISTERS || byte_count != 2 * quantity ||
      write.address + quantity > register_count || length < 6 + byte_count) {
    return std::nullopt;
  }
  for (int i = 0; i < quantity; ++i) {
    write.values.push_back(static_cast<uint16_t>((pdu[6 + 2 * i] << 8) | pdu[7 + 2 * i]));
  }
  return write;
}

void ApplyDriveWrite(const rig::DriveProfile& profile, const DriveWrite& write, DriveModel* model) {
  for (size_t i = 0; i < write.values.size(); ++i) {
    const int reg = write.address + static_cast<int>(i);
    const uint16_t value = write.values[i];
    const bool is_reset =
        !profile.fault_reset_values.empty() && value == profile.fault_reset_values[0];
    if (reg == profile.fault_reset_register && is_reset) {
      model->ResetFault();
    } else if (reg == profile.command_register) {
      if (value == profile.run_value)
        model->Run();
      else if (value == profile.stop_value)
        model->Stop();
    }
    if (reg == profile.setpoint_register) {
      model->SetSetpointHz(profile.setpoint_scaling.RegisterToHz(value));
    }
    if (profile.comm_watchdog && profile.comm_watchdog->register_address &&
        reg == *profile.comm_watchdog->register_address) {
      model->SetWatchdogS(value / profile.comm_watchdog->counts_per_s);
    }
  }
}

void RefreshDriveRegisters(const rig::DriveProfile& profile, const DriveModel& model,
                           uint16_t* registers, int register_count) {
  const auto in_map = [register_count](int address) {
    return address >= 0 && address < register_count;
  };
  const DriveModelState& s = model.state();
  uint16_t status = 0;
  if (model.output_active()) status |= profile.running_value & profile.running_mask;
  if (s.fault_code != 0) status |= profile.fault_mask;
  if (in_map(profile.status_register)) registers[profile.status_register] = status;
  const auto output = profile.output_scaling.HzToRegister(s.output_hz, "simulated output");
  if (in_map(profile.output_frequency_register)) {
    registers[profile.output_frequency_register] = output.ok() ? *output : 0xFFFF;
  }
  if (profile.oscillation_register && in_map(*profile.oscillation_register)) {
    const auto sensor = profile.oscillation_scaling.HzToRegister(s.sensor_hz, "simulated sensor");
    registers[*profile.oscillation_register] = sensor.ok() ? *sensor : 0xFFFF;
  }
  if (profile.fault_code_register && in_map(*profile.fault_code_register)) {
    const uint16_t code_bits = static_cast<uint16_t>((s.fault_code << profile.fault_code_shift) &
                                                     profile.fault_code_mask);
    uint16_t& word = registers[*profile.fault_code_register];
    if (*profile.fault_code_register == profile.status_register) {
      word = static_cast<uint16_t>((word & ~profile.fault_code_mask) | code_bits);
    } else {
      word = code_bits;
    }
  }
}

StatusOr<std::unique_ptr<DriveSim>> DriveSim::Start(const rig::DriveProfile& profile,
                                                    const DriveSimOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<DriveSim> sim(new DriveSim(profile, options));
  sim->mapping_ = modbus_mapping_new(0, 0, profile.MaxRegister() + 1, 0);
  if (sim->mapping_ == nullptr) {
    return InternalError(fmt::format("simulated drive: cannot allocate {} registers: {}",
                                     profile.MaxRegister() + 1, modbus_strerror(errno)));
  }
  FACEDYN_RETURN_IF_ERROR(options.is_rtu() ? sim->OpenSerial() : sim->Listen());
  sim->header_length_ = modbus_get_header_length(sim->ctx_);
  sim->RefreshRegisters();
  sim->last_advance_ = Clock::now();
  sim->thread_ = std::thread([raw = sim.get()] {
    if (raw->options_.is_rtu()) {
      raw->ServeRtu();
    } else {
      raw->Serve();
    }
  });
  return sim;
}

std::string DriveSim::Describe() const {
  if (options_.is_rtu()) return fmt::format("rtu {}", options_.rtu_device);
  return fmt::format("tcp {}:{}", options_.host, port_);
}

Status DriveSim::Listen() {
  ctx_ = modbus_new_tcp(options_.host.c_str(), options_.port);
  if (ctx_ == nullptr) {
    return InvalidArgumentError(
        fmt::format("simulated drive: cannot create a context for {}:{}: {}", options_.host,
                    options_.port, modbus_strerror(errno)));
  }
  listen_socket_ = modbus_tcp_listen(ctx_, 128);  // a burst of connects must not wait on SYN retries
  if (listen_socket_ == -1) {
    return UnavailableError(fmt::format("simulated drive: cannot listen on {}:{}: {}",
                                        options_.host, options_.port, modbus_strerror(errno)));
  }
  sockaddr_in bound{};
  socklen_t length = sizeof(bound);
  if (getsockname(listen_socket_, reinterpret_cast<sockaddr*>(&bound), &length) != 0) {
    return UnavailableError(fmt::format("simulated drive: getsockname: {}", std::strerror(errno)));
  }
  port_ = ntohs(bound.sin_port);
  return Status::Ok();
}

Status DriveSim::OpenSerial() {
  ctx_ = modbus_new_rtu(options_.rtu_device.c_str(), options_.baud, options_.parity,
                        options_.data_bits, options_.stop_bits);
  if (ctx_ == nullptr) {
    return InvalidArgumentError(
        fmt::format("simulated drive: cannot create an RTU context for {}: {}", options_.rtu_device,
                    modbus_strerror(errno)));
  }
  modbus_set_slave(ctx_, profile_.unit_id);
  if (modbus_connect(ctx_) == -1) {
    return UnavailableError(fmt::format("simulated drive: cannot open {}: {}", options_.rtu_device,
                                        modbus_strerror(errno)));
  }
  return Status::Ok();
}

DriveSim::~DriveSim() {
  stopping_ = true;
  if (thread_.joinable()) thread_.join();
  if (listen_socket_ != -1) ::close(listen_socket_);
  if (mapping_ != nullptr) modbus_mapping_free(mapping_);
  if (ctx_ != nullptr) {
    if (options_.is_rtu()) modbus_close(ctx_);
    modbus_free(ctx_);
  }
}

void DriveSim::ExceptionNextReplies(int count, int code) {
  exception_code_ = code;
  exception_replies_ = count;
}

void DriveSim::ForceFault(int code) {
  std::lock_guard<std::mutex> lock(model_mutex_);
  model_.ForceFault(code);
}

void DriveSim::SetSensorGain(double gain) {
  std::lock_guard<std::mutex> lock(model_mutex_);
  model_.SetSensorGain(gain);
}

void DriveSim::ScheduleTrip(double after_s, int code) {
  std::lock_guard<std::mutex> lock(model_mutex_);
  model_.ScheduleTrip(after_s, code);
}

DriveModelState DriveSim::state() const {
  std::lock_guard<std::mutex> lock(model_mutex_);
  return model_.state();
}

// Caller holds model_mutex_ (or the thread is not started yet).
void DriveSim::RefreshRegisters() {
  RefreshDriveRegisters(profile_, model_, mapping_->tab_registers, mapping_->nb_registers);
}

void DriveSim::AdvanceModel() {
  const auto now = Clock::now();
  std::lock_guard<std::mutex> lock(model_mutex_);
  // When the server thread was not scheduled for a while (a loaded machine), requests may be
  // waiting in the socket unread; advancing the watchdog by the whole gap would trip it for the
  // simulator's own stall. Model time therefore advances by at most kMaxStepS per loop, and
  // lags the wall clock only while the simulator is starved.
  constexpr double kMaxStepS = 0.05;
  model_.Advance(std::min(kMaxStepS, std::chrono::duration<double>(now - last_advance_).count()));
  RefreshRegisters();
  last_advance_ = now;
}

bool DriveSim::Answer(const uint8_t* query, int length) {
  if (link_cut_ || drop_requests_ > 0) {
    if (!link_cut_) --drop_requests_;
    ++requests_dropped_;
    return true;  // lost on the wire: neither applied nor answered
  }
  const double delay_s = reply_delay_s_;
  if (delay_s > 0.0) std::this_thread::sleep_for(std::chrono::duration<double>(delay_s));
  AdvanceModel();
  std::lock_guard<std::mutex> lock(model_mutex_);
  model_.NoteRequest();
  if (garble_replies_ > 0) {
    --garble_replies_;
    ++replies_garbled_;
    // Random bytes where the reply should be: a CRC error on RTU, a bad header on TCP.
    uint8_t noise[12];
    for (uint8_t& byte : noise) byte = static_cast<uint8_t>(garble_random_());
    const ssize_t written = ::write(modbus_get_socket(ctx_), noise, sizeof(noise));
    (void)written;
    return true;
  }
  if (exception_replies_ > 0) {
    --exception_replies_;
    return modbus_reply_exception(ctx_, query, static_cast<unsigned>(exception_code_.load())) != -1;
  }
  // Replies to reads carry the refreshed values; writes land in the mapping and are then
  // interpreted — but only writes the drive accepts. modbus_reply answers an illegal request
  // (an FC16 of 200 registers, an address past the map) with an exception and writes nothing,
  // and such a request must change nothing here either: a real drive does not act on a write
  // it refused (re-applying the mapping's run word restarted the motor).
  const std::optional<DriveWrite> write =
      DecodeAcceptedWrite(query + header_length_, length - header_length_, mapping_->nb_registers);
  if (modbus_reply(ctx_, query, length, mapping_) == -1) {
    spdlog::debug("simulated drive: reply failed: {}", modbus_strerror(errno));
    return false;
  }
  if (write) ApplyDriveWrite(profile_, *write, &model_);
  RefreshRegisters();
  ++requests_served_;
  return true;
}

void DriveSim::Serve() {
  // poll(), not select(): select's fd_set stops at FD_SETSIZE (1024) and a flood of idle
  // connections pushed descriptors past it (FD_SET out of bounds aborted the server). Clients
  // beyond kMaxClients are refused at accept, and a client silent for kClientIdleS is closed, so
  // idle connections cannot starve the one that drives the platform.
  constexpr size_t kMaxClients = 64;
  constexpr double kClientIdleS = 60.0;
  struct Client {
    int fd;
    Clock::time_point last_request;
  };
  std::vector<Client> clients;
  std::vector<pollfd> polled;
  uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
  while (!stopping_) {
    polled.clear();
    polled.push_back({listen_socket_, POLLIN, 0});
    for (const Client& client : clients) polled.push_back({client.fd, POLLIN, 0});
    const int timeout_ms = std::max(1, static_cast<int>(options_.step_s * 1e3));
    const int ready = ::poll(polled.data(), polled.size(), timeout_ms);
    AdvanceModel();
    const auto now = Clock::now();
    // Accept every pending connection (a burst must not wait one poll round each).
    for (bool pending = ready > 0 && (polled[0].revents & POLLIN); pending;) {
      const int fd = ::accept(listen_socket_, nullptr, nullptr);
      if (fd < 0) break;
      // libmodbus's modbus_receive select()s on the socket internally, so a descriptor at or
      // past FD_SETSIZE cannot be served at all (in a process with many files open).
      if (clients.size() >= kMaxClients || fd >= FD_SETSIZE) {
        spdlog::debug("simulated drive: refusing a connection: {} clients already", kMaxClients);
        ::close(fd);
      } else {
        clients.push_back({fd, now});
      }
      pollfd again{listen_socket_, POLLIN, 0};
      pending = ::poll(&again, 1, 0) > 0 && (again.revents & POLLIN);
    }
    // Serve the clients polled this round (a new client is polled from the next round on).
    std::vector<Client> kept;
    kept.reserve(clients.size());
    for (size_t i = 0; i < clients.size(); ++i) {
      Client client = clients[i];
      const short events = i + 1 < polled.size() ? polled[i + 1].revents : 0;
      if (ready > 0 && (events & (POLLIN | POLLHUP | POLLERR))) {
        modbus_set_socket(ctx_, client.fd);
        const int length = modbus_receive(ctx_, query);
        if (length == -1) {  // peer closed or sent garbage: drop the connection
          ::close(client.fd);
          continue;
        }
        client.last_request = now;
        if (length > 0) Answer(query, length);  // 0: addressed to another unit
      } else if (std::chrono::duration<double>(now - client.last_request).count() > kClientIdleS) {
        ::close(client.fd);
        continue;
      }
      kept.push_back(client);
    }
    clients.swap(kept);
  }
  for (const Client& client : clients) ::close(client.fd);
}

void DriveSim::ServeRtu() {
  uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
  const int fd = modbus_get_socket(ctx_);
  while (!stopping_) {
    fd_set readable;
    FD_ZERO(&readable);
    FD_SET(fd, &readable);
    timeval timeout{0, static_cast<suseconds_t>(options_.step_s * 1e6)};
    const int ready = select(fd + 1, &readable, nullptr, nullptr, &timeout);
    AdvanceModel();
    if (ready <= 0) continue;
    const int length = modbus_receive(ctx_, query);
    if (length == -1) {
      // A bad CRC, a half frame or line noise: a serial slave resynchronises on the silence
      // after it rather than giving up the line. A hung-up line (the peer closed its end)
      // stays readable, so back off instead of spinning.
      const int error = errno;
      modbus_flush(ctx_);
      if (error != EMBBADCRC && error != EMBBADDATA && error != ETIMEDOUT) {
        std::this_thread::sleep_for(std::chrono::duration<double>(options_.step_s));
      }
      continue;
    }
    if (length == 0) continue;  // addressed to another unit
    Answer(query, length);
  }
}

}  // namespace facedyn::sim
