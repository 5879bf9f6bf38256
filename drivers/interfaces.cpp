#include "drivers/interfaces.hpp"

namespace imucal::drivers {

const char* to_string(DriverErrc code) noexcept {
  switch (code) {
    case DriverErrc::not_connected: return "not connected";
    case DriverErrc::connect_failed: return "connect failed";
    case DriverErrc::timeout: return "timeout";
    case DriverErrc::connection_lost: return "connection lost";
    case DriverErrc::protocol_error: return "protocol error";
    case DriverErrc::crc_error: return "checksum error";
    case DriverErrc::device_rejected: return "rejected by device";
    case DriverErrc::interlock_open: return "interlock open";
    case DriverErrc::limit_exceeded: return "limit exceeded";
    case DriverErrc::axis_fault: return "axis fault";
    case DriverErrc::watchdog_expired: return "watchdog expired";
    case DriverErrc::alarm: return "alarm";
    case DriverErrc::invalid_argument: return "invalid argument";
    case DriverErrc::invalid_state: return "invalid state";
    case DriverErrc::stream_stalled: return "stream stalled";
    case DriverErrc::io_error: return "I/O error";
    case DriverErrc::unsupported: return "unsupported";
  }
  return "unknown driver error";
}

const char* to_string(DeviceState state) noexcept {
  switch (state) {
    case DeviceState::disconnected: return "disconnected";
    case DeviceState::connected: return "connected";
    case DeviceState::configured: return "configured";
    case DeviceState::active: return "active";
    case DeviceState::faulted: return "faulted";
  }
  return "unknown";
}

const char* to_string(TableMode mode) noexcept {
  switch (mode) {
    case TableMode::off: return "off";
    case TableMode::position: return "position";
    case TableMode::rate: return "rate";
    case TableMode::synthesis: return "synthesis";
  }
  return "unknown";
}

ImuFrame ImuSample::to_frame() const {
  ImuFrame f;
  f.t_ns = t_ns;
  for (int j = 0; j < 3; ++j) {
    const auto i = static_cast<std::size_t>(j);
    f.dtheta_rad[j] = dtheta_rad[i];
    f.dv_mps[j] = dv_mps[i];
  }
  return f;
}

TempSample ImuTemperatures::to_temp_sample() const {
  TempSample s;
  s.t_ns = t_ns;
  for (int g = 0; g < 3; ++g) {
    double sum = 0.0;
    for (int k = 0; k < 8; ++k) sum += coil_C[static_cast<std::size_t>(8 * g + k)];
    s.gyro_C[g] = sum / 8.0;
    s.accel_C[g] = accel_C[static_cast<std::size_t>(g)];
  }
  return s;
}

}  // namespace imucal::drivers
