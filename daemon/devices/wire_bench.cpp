#include "daemon/devices/wire_bench.hpp"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "core/expect_value.hpp"
#include "core/hermite.hpp"
#include "core/number_text.hpp"
#include "core/units.hpp"
#include "drivers/link_imu.hpp"
#include "drivers/modbus_chamber.hpp"
#include "drivers/power_relay.hpp"
#include "drivers/register_map.hpp"
#include "drivers/tcp_table.hpp"
#include "sim/sim_devices.hpp"

namespace imucal::daemon {

namespace dr = imucal::drivers;

namespace {

constexpr std::int64_t kChamberReadPeriod_ns = 250'000'000;  // device time
// Accelerated, the chamber is read no more often than this in host time (a Modbus round trip
// each): at 500x every 20 ms is every 10 s of program, still many times the air's lag.
constexpr std::int64_t kChamberReadMinPeriod_host_ns = 20'000'000;
constexpr std::int64_t kReadHistory_ns = 10'000'000'000;  // table reads kept for interpolation
// Rate tracking of sine pieces: the program's rate a little ahead (the controller ramps towards a
// new demand at its acceleration limit) plus this gain times the angle error.
constexpr double kTrackLookahead_s = 0.02;
constexpr double kTrackGain_per_s = 2.0;
constexpr double kAtTarget_deg = 1e-4;

template <class T>
void require(const dr::Result<T>& r, const std::string& what) {
  if (!r) throw std::runtime_error(what + ": " + r.error().message);
}

// The IMU's transport as configured: a CAN_RAW socket on the interface or a connection to a Unix
// SOCK_SEQPACKET socket that carries the same frame images (a CAN gateway, `imucal sim-devices`),
// a serial device, or a UDP port. Only the CAN descriptor is opened here; the driver's connect()
// opens the others.
dr::Result<std::unique_ptr<dr::ImuTransport>> imu_transport(const ImuDeviceConfig& imu) {
  using Transport = std::unique_ptr<dr::ImuTransport>;
  switch (imu.link.transport) {
    case dr::link::Transport::serial: return Transport(dr::serial_transport(imu.serial_device, imu.link));
    case dr::link::Transport::udp:
      return Transport(dr::udp_transport(imu.udp_bind, imu.udp_port, imu.udp_peer_host, imu.udp_peer_port));
    case dr::link::Transport::socketcan: break;
  }
  if (!imu.interface.empty()) {
    auto fd = dr::open_socketcan(imu.interface, imu.framing == dr::can::Framing::fd);
    if (!fd) return fd.error();
    return Transport(dr::socketcan_transport(*fd, imu.link, imu.framing, "CAN interface '" + imu.interface + "'"));
  }
  const std::string who = "cannot connect to the IMU socket '" + imu.socket_path + "': ";
  sockaddr_un addr{};
  if (imu.socket_path.empty() || imu.socket_path.size() >= sizeof addr.sun_path)
    return dr::DriverError{dr::DriverErrc::invalid_argument, who + "not a usable socket path"};
  const int fd = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) return dr::DriverError{dr::DriverErrc::connect_failed, who + "socket(AF_UNIX, SOCK_SEQPACKET): " + std::strerror(errno)};
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, imu.socket_path.data(), imu.socket_path.size());
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    const int e = errno;
    ::close(fd);
    return dr::DriverError{dr::DriverErrc::connect_failed,
                           who + std::strerror(e) + " (is the CAN gateway or `imucal sim-devices` running there?)"};
  }
  return Transport(dr::socketcan_transport(fd, imu.link, imu.framing, "socket " + imu.socket_path));
}

}  // namespace

struct WireBench::Devices {
  std::unique_ptr<dr::TcpTable> table;
  std::unique_ptr<dr::ModbusChamber> chamber;
  std::unique_ptr<dr::LinkImu> imu;
  std::unique_ptr<dr::PowerRelay> relay;  // when configured
  // How far the bring-up got: what a failed start must park.
  bool table_connected = false;
  bool chamber_active = false;
};

// ------------------------------------------------------------------------------------------------
// The facades the sequencer sees.

class WireBench::TableFacade final : public Table {
 public:
  explicit TableFacade(WireBench& b) : b_(b) {}
  DeviceResult home() override {
    if (auto r = b_.dev_->table->interlock_close(); !r) return DeviceResult::failure(r.error().message);
    if (auto r = b_.reposition(Eigen::Vector3d::Zero()); !r.ok) return r;
    b_.homed_ = true;
    return DeviceResult::success();
  }
  DeviceResult close_interlock() override {
    if (auto r = b_.dev_->table->interlock_close(); !r) return DeviceResult::failure(r.error().message);
    return DeviceResult::success();
  }
  DeviceResult open_interlock() override {
    b_.following_ = false;
    // The safe hold takes over from a refused demand; what is still wrong shows in the status.
    b_.table_error_.clear();
    if (auto r = b_.dev_->table->interlock_open(); !r) return DeviceResult::failure(r.error().message);
    b_.modes_.fill(dr::TableMode::off);
    b_.read_table();  // whoever looks next sees the interlock open
    return DeviceResult::success();
  }
  DeviceResult stop() override { return b_.stop_motion(); }
  DeviceResult start_program_at(double t_s) override {
    if (!b_.homed_) return DeviceResult::failure("table is not homed");
    // Already following and the next frame is the checkpoint's first: the program goes on as it
    // is (a segment boundary passed without interruption).
    const auto t_ns = std::llround(t_s * units::kNsPerS);
    if (b_.following_ && b_.table_error_.empty() && b_.delivered_t_ns_ <= t_ns && t_ns < b_.delivered_t_ns_ + b_.dt_ns_)
      return DeviceResult::success();
    if (auto r = b_.stop_motion(); !r.ok) return r;
    const Eigen::Vector3d pose_deg = b_.program_.evaluate(t_s).angle_rad * units::kRadToDeg;
    if (auto r = b_.reposition(pose_deg); !r.ok) return r;
    b_.anchor_host_ns_ = dr::host_time_ns();
    b_.anchor_t_s_ = t_s;
    b_.delivered_t_ns_ = t_ns;
    b_.first_sequence_.reset();
    b_.pending_.clear();
    b_.pending_temps_.clear();
    b_.next_piece_ = 0;
    while (b_.next_piece_ + 1 < b_.program_.pieces.size() && b_.program_.pieces[b_.next_piece_].t1_s <= t_s)
      ++b_.next_piece_;
    b_.table_error_.clear();
    b_.following_ = true;
    b_.follow_program();
    if (!b_.table_error_.empty()) return DeviceResult::failure(b_.table_error_);
    return DeviceResult::success();
  }
  TableState state() const override {
    TableState s = b_.table_state_;
    s.homed = b_.homed_;
    if (!b_.table_error_.empty() && s.fault.empty()) s.fault = b_.table_error_;
    return s;
  }

 private:
  WireBench& b_;
};

class WireBench::ChamberFacade final : public Chamber {
 public:
  explicit ChamberFacade(WireBench& b) : b_(b) {}
  DeviceResult set_setpoint(double setpoint_C) override {
    if (auto r = b_.dev_->chamber->set_setpoint(setpoint_C); !r) return DeviceResult::failure(r.error().message);
    b_.chamber_state_.setpoint_C = setpoint_C;
    return DeviceResult::success();
  }
  ChamberState state() const override { return b_.chamber_state_; }

 private:
  WireBench& b_;
};

class WireBench::PowerFacade final : public PowerSwitch {
 public:
  explicit PowerFacade(dr::PowerRelay& relay) : relay_(relay) {}
  DeviceResult set_power(bool on) override {
    if (auto r = relay_.set_power(on); !r) return DeviceResult::failure(r.error().message);
    return DeviceResult::success();
  }
  double off_s() const override { return relay_.config().off_s; }
  std::string describe() const override { return relay_.describe(); }

 private:
  dr::PowerRelay& relay_;
};

class WireBench::ImuFacade final : public Imu {
 public:
  explicit ImuFacade(WireBench& b) : b_(b) {}
  DeviceResult read(FrameBatch& out, std::int64_t until_t_ns) override {
    out.clear();
    b_.service(10);
    if (!b_.imu_error_.empty()) return DeviceResult::failure(b_.imu_error_);
    // A frame leaves once a table read after it exists (its angles are interpolated).
    while (!b_.pending_.empty() && b_.pending_.front().program_t_ns <= until_t_ns) {
      PendingSample& p = b_.pending_.front();
      if (!b_.interpolate(p.host_t_ns, p.frame.table_deg)) break;
      out.frames.push_back(p.frame);
      b_.delivered_t_ns_ = p.program_t_ns;
      b_.pending_.pop_front();
    }
    if (!out.frames.empty()) {
      b_.fire_faults(b_.delivered_t_ns_);
      const std::int64_t last_ns = out.frames.back().t_ns;
      auto end = std::find_if(b_.pending_temps_.begin(), b_.pending_temps_.end(),
                              [&](const TempSample& t) { return t.t_ns > last_ns; });
      out.temps.assign(b_.pending_temps_.begin(), end);
      b_.pending_temps_.erase(b_.pending_temps_.begin(), end);
    }
    return DeviceResult::success();
  }
  ImuState state() const override { return {b_.dev_->imu->state() != dr::DeviceState::faulted && b_.imu_error_.empty()}; }
  bool reports_serial() const override { return b_.addresses_.imu.link.reports_serial(); }
  std::optional<std::string> reported_serial(double wait_s) override {
    const std::int64_t deadline_ns = dr::host_time_ns() + std::llround(wait_s * units::kNsPerS);
    while (!b_.dev_->imu->reported_serial() && dr::host_time_ns() < deadline_ns) b_.wait(0.05);
    return b_.dev_->imu->reported_serial();
  }
  RecordingMeta recording_meta() const override {
    RecordingMeta m;
    m.site = b_.settings_.site;
    m.imu_serial = b_.addresses_.imu.serial;
    m.rate_hz = b_.addresses_.imu.rate_hz;
    m.segments = b_.program_.segments();
    // Counts under the LSB when the IMU sends integer increments; doubles otherwise.
    m.gyro_lsb_rad = b_.addresses_.imu.link.gyro_increment_lsb_rad();
    m.accel_lsb_mps = b_.addresses_.imu.link.accel_increment_lsb_mps();
    m.program_json = b_.program_.source_json;
    m.truth_json = b_.truth_json_;  // only a simulated IMU has a truth
    m.table = b_.settings_.table;
    return m;
  }

 private:
  WireBench& b_;
};

// ------------------------------------------------------------------------------------------------

WireBench::WireBench(const motion::Program& program, const WireBenchSettings& settings, const DeviceAddresses& devices)
    : program_(program),
      settings_(settings),
      addresses_(devices),
      dt_ns_(std::llround(units::kNsPerS / settings.rate_hz)),
      epoch_ns_(dr::host_time_ns()) {
  imu_link_ = addresses_.imu.describe();
  start(-1);
}

WireBench::WireBench(const motion::Program& program, const WireBenchSettings& settings, const SimWireSettings& simulated)
    : program_(program),
      settings_(settings),
      dt_ns_(std::llround(units::kNsPerS / settings.rate_hz)),
      time_scale_(simulated.time_scale),
      epoch_ns_(dr::host_time_ns()) {
  if (!(time_scale_ > 0.0)) throw std::runtime_error("sim-wire: the time scale must be positive");
  sim::SimDevicesConfig sim;
  sim.time_scale = time_scale_;
  for (std::size_t a = 0; a < 3; ++a)
    for (auto& mode : sim.servo.limits[a]) mode = table_limit_setting(settings.limits.axis[a]);
  sim.chamber_map = kSimWireChamberMap;
  sim.chamber_start_C = simulated.chamber_start_C;
  sim.chamber_tau_s = simulated.chamber_tau_s;
  sim.imu.framing = dr::can::Framing::fd;
  sim.imu.rate_hz = settings.rate_hz;
  sim.imu.seed = simulated.seed;
  sim.imu.truth = simulated.truth;
  sim.imu.site = settings.site;
  sim.imu.temperature_C = simulated.chamber_start_C;
  // Temperature messages at 10 per host second whatever the scale (one per 50 s of program at
  // 500x, plenty for air that moves over minutes): the link's bandwidth goes to the samples.
  sim.imu.temp_rate_hz = sim.imu.temp_rate_hz / time_scale_;
  sim.imu_serial = simulated.imu_serial.empty() ? "SIM-WIRE-" + std::to_string(simulated.seed) : simulated.imu_serial;
  sim_ = std::make_unique<sim::SimDevices>(sim);

  // The addresses an operator would configure for these devices.
  addresses_.table.host = "127.0.0.1";
  addresses_.table.port = sim_->table_port();
  addresses_.chamber.host = "127.0.0.1";
  addresses_.chamber.port = sim_->chamber_port();
  addresses_.chamber.map = dr::load_register_map(kSimWireChamberMap);
  addresses_.chamber.safe_setpoint_C = simulated.chamber_safe_setpoint_C;
  addresses_.imu.framing = dr::can::Framing::fd;
  addresses_.imu.link_name = sim.imu_link;
  addresses_.imu.link = dr::link::load_imu_link(sim.imu_link);
  dr::link::resolve_per_unit_lsb(addresses_.imu.link, sim_->gyro_lsb_rad(), sim_->accel_lsb_mps());
  addresses_.imu.rate_hz = settings.rate_hz;
  addresses_.imu.serial = sim.imu_serial;
  // The simulated chamber's digital output 0 is the IMU's supply (normally open, powered).
  dr::PowerRelayConfig relay;
  relay.host = "127.0.0.1";
  relay.port = sim_->chamber_port();
  relay.coil = sim::SimDevices::kImuPowerCoil;
  relay.off_s = 2.0;  // the simulated IMU has no supply to drain: short rehearsals
  addresses_.power_relay = relay;
  truth_json_ = imu_model_to_json_text(simulated.truth);
  for (const SimFault& f : simulated.faults) faults_.push_back({f});
  disk_ = simulated.disk;
  imu_link_ = "a socket pair";

  // The IMU's CAN link: a socket pair carrying struct canfd_frame images (no AF_CAN here).
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) != 0)
    throw std::runtime_error(std::string("sim-wire: socketpair(AF_UNIX, SOCK_SEQPACKET) for the IMU link failed: ") +
                             std::strerror(errno));
  try {
    sim_->attach_imu(sv[1]);
  } catch (...) {
    ::close(sv[0]);  // neither end is owned by anyone yet
    ::close(sv[1]);
    throw;
  }
  start(sv[0]);
}

void WireBench::start(int imu_fd) {
  const ImuDeviceConfig& imu = addresses_.imu;
  if (std::abs(settings_.rate_hz - imu.rate_hz) > 1e-9 * imu.rate_hz) {
    if (imu_fd >= 0) ::close(imu_fd);
    char text[200];
    std::snprintf(text, sizeof text,
                  "the campaign's rate %g Hz is not the IMU's: it samples at %g Hz (config.devices.imu.rate_hz)",
                  settings_.rate_hz, imu.rate_hz);
    throw std::runtime_error(text);
  }
  // The controller enforces the program's limits wherever the device configuration names none.
  for (std::size_t a = 0; a < 3; ++a)
    for (auto& mode : addresses_.table.limits[a])
      if (!mode) mode = table_limit_setting(settings_.limits.axis[a]);
  // A quarter of the watchdog period leaves room for a late service step or two.
  if (addresses_.table.watchdog_s > 0.0)
    keep_alive_ns_ = std::max<std::int64_t>(50'000'000, std::llround(addresses_.table.watchdog_s * units::kNsPerS / 4));

  dev_ = std::make_unique<Devices>();
  // The IMU link first: opening it moves nothing, and without it no run can record.
  open_imu(imu_fd);
  dev_->table = std::make_unique<dr::TcpTable>(addresses_.table);
  dev_->chamber = std::make_unique<dr::ModbusChamber>(addresses_.chamber);

  try {
    require(dev_->table->connect(), "table: connect");
    dev_->table_connected = true;
    require(dev_->table->configure(), "table: configure");
    require(dev_->chamber->connect(), "chamber: connect");
    require(dev_->chamber->configure(), "chamber: configure");
    require(dev_->chamber->activate(), "chamber: activate");
    dev_->chamber_active = true;
    // The chamber's state is what it reads, from the start (a real chamber is wherever it is).
    auto reading = dev_->chamber->read();
    require(reading, "chamber: first read");
    chamber_state_.temperature_C = reading->process_C;
    chamber_state_.setpoint_C = reading->setpoint_C;
    chamber_state_.connected = true;
    next_chamber_read_ns_ = dr::host_time_ns() + std::max(kChamberReadMinPeriod_host_ns, host_ns(kChamberReadPeriod_ns * 1e-9));
    require(dev_->imu->configure(), "IMU on " + imu_link_ + ": configure");
    require(dev_->imu->activate(), "IMU on " + imu_link_ + ": activate");
    if (addresses_.power_relay) check_power_relay(*addresses_.power_relay);
  } catch (const std::exception& e) {
    std::string message = e.what();
    park_after_failed_start(message);
    throw std::runtime_error(message);
  }

  table_ = std::make_unique<TableFacade>(*this);
  chamber_ = std::make_unique<ChamberFacade>(*this);
  imu_ = std::make_unique<ImuFacade>(*this);
  if (dev_->relay) power_ = std::make_unique<PowerFacade>(*dev_->relay);
  service(0);
}

void WireBench::open_imu(int imu_fd) {
  const ImuDeviceConfig& imu = addresses_.imu;
  dr::LinkImuConfig imu_config;
  imu_config.name = imu.serial;
  imu_config.link = imu.link;
  // The driver sees the samples arrive at the IMU's rate times the time scale (their time tags
  // tick in host time, sim_world.hpp).
  imu_config.rate_hz = imu.rate_hz * time_scale_;
  imu_config.stall_timeout = std::chrono::milliseconds(imu.stall_timeout_ms);
  imu_config.transport_delay_ns = imu.transport_delay_ns;
  auto transport = imu_fd >= 0 ? dr::Result<std::unique_ptr<dr::ImuTransport>>(
                                     dr::socketcan_transport(imu_fd, imu.link, imu.framing, imu_link_))
                               : imu_transport(imu);
  if (transport) {
    dev_->imu = std::make_unique<dr::LinkImu>(std::move(*transport), imu_config);
    if (auto r = dev_->imu->connect(); !r) transport = r.error();
  }
  if (!transport)
    throw std::runtime_error("IMU on " + imu_link_ + ": " + transport.error().message +
                             "; nothing was moved (the table and the chamber were not contacted)");
}

void WireBench::check_power_relay(const dr::PowerRelayConfig& relay) {
  dev_->relay = std::make_unique<dr::PowerRelay>(relay);
  // A program that cycles the IMU's power needs the relay hours later: checked now, and the IMU
  // that has just answered must be powered by it (else the coil or its sense is wrong).
  const auto segments = program_.segments();
  if (std::none_of(segments.begin(), segments.end(), [](const SegmentInfo& g) { return g.kind == "power-cycle"; }))
    return;
  auto powered = dev_->relay->powered();
  require(powered, "power relay");
  if (!*powered)
    throw std::runtime_error(dev_->relay->describe() + " says the IMU is unpowered, but the IMU answers: "
                             "check the coil and on_when_set (config.devices.power_relay)");
}

// A start that failed half way leaves nothing running: the table's axes off with the interlock
// open, the chamber at its safe set point, the IMU stream stopped. The message tells what was done.
void WireBench::park_after_failed_start(std::string& message) {
  (void)dev_->imu->safe_stop();
  if (dev_->table_connected) {
    if (auto r = dev_->table->safe_stop(); r)
      message += "; the table was parked (axes off, interlock open)";
    else
      message += "; parking the table failed too: " + r.error().message;
  } else {
    message += "; the table was not moved";
  }
  if (dev_->chamber_active) {
    if (auto r = dev_->chamber->safe_stop(); !r) message += "; the chamber's safe stop failed: " + r.error().message;
  }
}

void WireBench::resuming_after(double t_s) {
  for (InjectedFault& f : faults_)
    if (!f.fired && f.fault.at_s <= t_s) f.fired = f.over = true;
}

WireBench::~WireBench() {
  for (const InjectedFault& f : faults_)
    if (f.fault.kind == SimFault::Kind::DiskFull && f.fired && !f.over && disk_) disk_.set_full(false);
  // The sequencer parked the table and the chamber; stop the stream and close the links.
  (void)dev_->imu->safe_stop();
  dev_->imu->disconnect();
  dev_->chamber->disconnect();
  dev_->table->disconnect();
}

Table& WireBench::table() { return *table_; }
Chamber& WireBench::chamber() { return *chamber_; }
Imu& WireBench::imu() { return *imu_; }
PowerSwitch* WireBench::power_switch() { return power_.get(); }
double WireBench::now_s() const { return static_cast<double>(device_ns(dr::host_time_ns() - epoch_ns_)) / units::kNsPerS; }

std::int64_t WireBench::device_ns(std::int64_t host_span_ns) const {
  return time_scale_ == 1.0 ? host_span_ns : std::llround(static_cast<double>(host_span_ns) * time_scale_);
}

std::int64_t WireBench::host_ns(double device_s) const { return std::llround(device_s / time_scale_ * units::kNsPerS); }

void WireBench::wait(double seconds) {
  const auto deadline = dr::host_time_ns() + host_ns(seconds);
  for (;;) {
    const std::int64_t left_ns = deadline - dr::host_time_ns();
    if (left_ns <= 0) break;
    service(static_cast<int>(std::min<std::int64_t>(10, left_ns / 1'000'000 + 1)));
  }
}

std::string WireBench::describe() const {
  char rate[32];
  std::snprintf(rate, sizeof rate, "%g Hz", settings_.rate_hz);
  const std::string devices = dev_->table->describe() + "; " + dev_->chamber->describe() + "; " +
                              dev_->imu->describe() + " on " + imu_link_ + " at " + rate;
  if (sim_)
    return "simulated devices on loopback through the real drivers, " +
           (time_scale_ == 1.0 ? std::string("in real time") : number_text(time_scale_) + "x real time") + ": " + devices;
  return "devices at the configured addresses through the real drivers: " + devices;  // the IMU named by its serial
}

std::int64_t WireBench::anchor_ns() const { return std::llround(anchor_t_s_ * units::kNsPerS); }

void WireBench::service(int max_wait_ms) {
  dr::ImuBatch batch;
  if (auto r = dev_->imu->poll(batch, std::chrono::milliseconds(max_wait_ms)); !r) {
    imu_error_ = r.error().message;  // names the IMU; the sequencer says "IMU:"
  } else {
    imu_error_.clear();
  }
  if (following_) {
    for (const dr::ImuSample& s : batch.samples) {
      if (s.t_ns <= anchor_host_ns_) continue;  // sensed before the table followed the program
      if (!first_sequence_) {
        first_sequence_ = s.sequence;
        first_program_t_ns_ = anchor_ns() + dt_ns_;
      }
      const std::uint32_t periods = s.sequence - *first_sequence_;  // wraps like the counter
      PendingSample p;
      p.host_t_ns = s.t_ns;
      p.program_t_ns = first_program_t_ns_ + static_cast<std::int64_t>(periods) * dt_ns_;
      p.frame = s.to_frame();
      p.frame.t_ns = p.program_t_ns;
      // A sample the IMU marks faulty must not be recorded as good data: the sequencer sees a
      // corrupt frame and suspends.
      if (s.status_fault) p.frame.dtheta_rad.setConstant(std::nan(""));
      pending_.push_back(p);
    }
    for (const dr::ImuTemperatures& t : batch.temperatures) {
      if (t.t_ns <= anchor_host_ns_) continue;
      TempSample sample = t.to_temp_sample();
      sample.t_ns = anchor_ns() + device_ns(t.t_ns - anchor_host_ns_);
      sample.chamber_C = chamber_state_.temperature_C;
      sample.chamber_setpoint_C = chamber_state_.setpoint_C;
      if (pending_temps_.empty() || sample.t_ns > pending_temps_.back().t_ns) pending_temps_.push_back(sample);
    }
  }
  read_table();
  const std::int64_t now_ns = dr::host_time_ns();
  if (now_ns >= next_chamber_read_ns_) {
    next_chamber_read_ns_ = now_ns + std::max(kChamberReadMinPeriod_host_ns, host_ns(kChamberReadPeriod_ns * 1e-9));
    if (auto r = dev_->chamber->read(); r) {
      chamber_state_.temperature_C = r->process_C;
      chamber_state_.setpoint_C = r->setpoint_C;
      chamber_state_.connected = true;
    } else {
      chamber_state_.connected = false;
    }
  }
  if (following_) follow_program();
  keep_alive();
  expire_faults();
}

// sim_faults of a sim-wire campaign, on the simulated devices' own injection points: the bench
// then sees them as it would see a real fault, through the drivers only.
void WireBench::fire_faults(std::int64_t program_t_ns) {
  const std::int64_t now_ns = dr::host_time_ns();
  for (InjectedFault& f : faults_) {
    if (f.fired || program_t_ns < std::llround(f.fault.at_s * units::kNsPerS)) continue;
    f.fired = true;
    // Its duration is program time: host time divided by the scale.
    f.until_ns = now_ns + host_ns(f.fault.duration_s);
    const auto pause = std::chrono::milliseconds(host_ns(f.fault.duration_s) / 1'000'000);
    switch (f.fault.kind) {
      case SimFault::Kind::ChamberOffset:
        sim_->chamber().set_reading_offset(f.fault.offset_C);
        break;
      case SimFault::Kind::ImuDropout:
        sim_->with_imu([&](sim::SimImu& imu) { imu.pause(pause); });
        break;
      case SimFault::Kind::ImuCorrupt:
        // Damaged frames on the link: the driver's CRC check drops them, the sequencer sees a gap.
        sim_->with_imu([&](sim::SimImu& imu) { imu.corrupt_next_samples(static_cast<int>(f.fault.frames)); });
        break;
      case SimFault::Kind::ImuDrop:
        // Samples lost on the link (never sent): the driver sees the sequence counter jump, a gap.
        sim_->with_imu([&](sim::SimImu& imu) { imu.drop_next_samples(static_cast<int>(f.fault.frames)); });
        break;
      case SimFault::Kind::ImuBytesDrop:
        // Bytes lost on the link: each damaged frame is too short for its description, the
        // driver refuses it, the sequencer sees a gap.
        sim_->with_imu([&](sim::SimImu& imu) { imu.drop_byte_of_next_samples(static_cast<int>(f.fault.frames)); });
        break;
      case SimFault::Kind::ChamberCorrupt:
        // Replies the Modbus client must reject (libmodbus: invalid data); the driver retries.
        sim_->chamber().corrupt_next_replies(static_cast<int>(f.fault.frames));
        break;
      case SimFault::Kind::DropConnection:
        // The controller closes its connections; the driver's next request reconnects.
        if (f.fault.device == "table") {
          sim_->table().drop_connections();
        } else {
          sim_->chamber().drop_connections();
        }
        break;
      case SimFault::Kind::DiskFull:
        if (disk_) disk_.set_full(true);
        break;
      case SimFault::Kind::Disconnect:
        // A device that stops answering; the IMU's link cannot be reopened within a run, so the
        // IMU goes silent rather than closing it.
        if (f.fault.device == "table") {
          sim_->table().set_silent(true);
        } else if (f.fault.device == "chamber") {
          sim_->chamber().set_silent(true);
        } else {
          sim_->with_imu([&](sim::SimImu& imu) { imu.pause(pause); });
        }
        break;
      case SimFault::Kind::TableFault:
        sim_->table().trip_interlock();  // the panel's emergency stop: the axes brake, demands are refused
        break;
      case SimFault::Kind::RelayStuck:
        sim_->chamber().set_outputs_forced(true);  // the IMU's supply forced on by hand
        break;
    }
  }
}

void WireBench::expire_faults() {
  const std::int64_t now_ns = dr::host_time_ns();
  for (InjectedFault& f : faults_) {
    if (!f.fired || f.over || now_ns < f.until_ns) continue;
    f.over = true;
    if (f.fault.kind == SimFault::Kind::ChamberOffset) sim_->chamber().set_reading_offset(0.0);
    if (f.fault.kind == SimFault::Kind::RelayStuck) sim_->chamber().set_outputs_forced(false);
    if (f.fault.kind == SimFault::Kind::DiskFull && disk_) disk_.set_full(false);
    if (f.fault.kind == SimFault::Kind::Disconnect && f.fault.device == "table") sim_->table().set_silent(false);
    if (f.fault.kind == SimFault::Kind::Disconnect && f.fault.device == "chamber") sim_->chamber().set_silent(false);
  }
}

dr::Result<void> WireBench::demand(int axis, dr::TableMode mode, double value) {
  auto r = mode == dr::TableMode::position ? dev_->table->demand_position(axis, value)
                                           : dev_->table->demand_rate(axis, value);
  if (r) demands_[static_cast<std::size_t>(axis)] = {mode, value, dr::host_time_ns()};
  return r;
}

// The table's watchdog drops an axis that hears nothing for its period: repeating the demand
// under way feeds it without changing the motion (a hold stays a hold, a ramp goes on).
void WireBench::keep_alive() {
  if (keep_alive_ns_ == 0) return;
  const std::int64_t now_ns = dr::host_time_ns();
  for (int a = 0; a < 3; ++a) {
    const AxisDemand d = demands_[static_cast<std::size_t>(a)];
    if (modes_[static_cast<std::size_t>(a)] == dr::TableMode::off || d.mode != modes_[static_cast<std::size_t>(a)]) continue;
    // A refused repeat shows in the next status read (watchdog expired, interlock open).
    if (now_ns - d.sent_ns >= keep_alive_ns_) (void)demand(a, d.mode, d.value);
  }
}

void WireBench::read_table() {
  auto positions = dev_->table->read_positions();
  auto status = positions ? dev_->table->read_status() : dr::Result<dr::TableStatus>(positions.error());
  if (!positions || !status) {
    table_state_.connected = false;
    return;
  }
  table_state_.connected = true;
  TableRead read;
  read.t_ns = positions->t_ns;
  read.angle_deg = positions->angle_deg;
  read.rate_dps = positions->rate_dps;
  if (reads_.empty() || read.t_ns > reads_.back().t_ns) reads_.push_back(read);
  while (reads_.size() > 2 && reads_.front().t_ns < read.t_ns - kReadHistory_ns) reads_.pop_front();
  table_state_.angle_deg = Eigen::Vector3d(read.angle_deg[0], read.angle_deg[1], read.angle_deg[2]);
  table_state_.rate_dps = Eigen::Vector3d(read.rate_dps[0], read.rate_dps[1], read.rate_dps[2]);
  table_state_.interlock_closed = status->interlock == dr::InterlockState::closed;
  table_state_.moving = false;
  table_state_.fault.clear();
  // While the program is followed the daemon alone changes the interlock and the modes: the
  // interlock open (the emergency stop at the table) or an axis dropped to off means the table
  // no longer does what the frames' program times say.
  if (following_ && !table_state_.interlock_closed)
    table_state_.fault = "the interlock opened at the table while following the program (emergency stop?)";
  for (std::size_t a = 0; a < 3; ++a) {
    const dr::AxisStatus& axis = status->axes[a];
    if (following_ && table_state_.fault.empty() && modes_[a] != dr::TableMode::off && axis.mode == dr::TableMode::off)
      table_state_.fault = std::string(motion::kAxisNames[a]) + " axis dropped to off while following the program";
    modes_[a] = axis.mode;
    table_state_.moving = table_state_.moving || axis.moving;
    if (axis.fault || axis.watchdog_expired)
      table_state_.fault = std::string(motion::kAxisNames[a]) + " axis: " +
                           (axis.at_limit ? "position limit hit" : axis.watchdog_expired ? "watchdog expired" : "fault");
  }
}

bool WireBench::interpolate(std::int64_t host_ns, Eigen::Vector3d& angle_deg) const {
  if (reads_.size() < 2 || host_ns < reads_.front().t_ns || host_ns > reads_.back().t_ns) return false;
  auto hi = std::lower_bound(reads_.begin(), reads_.end(), host_ns,
                             [](const TableRead& r, std::int64_t t) { return r.t_ns < t; });
  if (hi == reads_.begin()) ++hi;
  const TableRead& r0 = *(hi - 1);
  const TableRead& r1 = *hi;
  const double h_s = static_cast<double>(device_ns(r1.t_ns - r0.t_ns)) / units::kNsPerS;  // rates are per device second
  const double u = static_cast<double>(host_ns - r0.t_ns) / static_cast<double>(r1.t_ns - r0.t_ns);
  // Cubic Hermite on angles and rates: exact for the controller's constant-acceleration pieces
  // up to the rate kinks between reads.
  for (std::size_t a = 0; a < 3; ++a)
    angle_deg[static_cast<Eigen::Index>(a)] =
        cubic_hermite(r0.angle_deg[a], r0.rate_dps[a], r1.angle_deg[a], r1.rate_dps[a], h_s, u);
  return true;
}

std::optional<double> WireBench::program_time_s(std::int64_t host_ns) const {
  if (!following_) return std::nullopt;
  return anchor_t_s_ + static_cast<double>(device_ns(host_ns - anchor_host_ns_)) / units::kNsPerS;
}

// The demands of every piece that has begun, then the rate of the sine pieces under way.
void WireBench::follow_program() {
  // Called only while the program is followed (it has a time then).
  const double t_s = expect_value(program_time_s(dr::host_time_ns()), "the program's time while it is followed");
  while (next_piece_ < program_.pieces.size() && program_.pieces[next_piece_].t0_s <= t_s + 1e-9) {
    if (!demand_piece(next_piece_)) return;
    ++next_piece_;
  }
  track_sines();
}

bool WireBench::demand_piece(std::size_t index) {
  const motion::Piece& piece = program_.pieces[index];
  auto fail = [&](int axis, const dr::DriverError& e) {
    table_error_ = "following segment '" + piece.segment + "', " + motion::kAxisNames[static_cast<std::size_t>(axis)] +
                   " axis: " + e.message;
    return false;
  };
  for (int a = 0; a < 3; ++a) {
    const auto i = static_cast<std::size_t>(a);
    const motion::AxisFunc& f = piece.axis[i];
    const bool positional = f.kind == motion::AxisFunc::Kind::Const || f.kind == motion::AxisFunc::Kind::Cycloid;
    const dr::TableMode mode = positional ? dr::TableMode::position : dr::TableMode::rate;
    const motion::AxisLimits& limits = settings_.limits.axis[i];
    // A ramp sets the rate-mode acceleration limit to its own; anything else runs at the limits.
    const bool ramp = f.kind == motion::AxisFunc::Kind::Quadratic && f.alpha != 0.0;
    if (ramp || rate_limit_changed_[i]) {
      dr::AxisLimitSetting setting = table_limit_setting(limits);
      if (ramp) setting.accel_dps2 = std::min(std::abs(f.alpha) * units::kRadToDeg, limits.accel_dps2);
      if (auto r = dev_->table->set_limits(a, dr::TableMode::rate, setting); !r) return fail(a, r.error());
      rate_limit_changed_[i] = ramp;
    }
    if (modes_[i] != mode) {
      if (auto r = dev_->table->set_mode(a, mode); !r) return fail(a, r.error());
      modes_[i] = mode;
    }
    dr::Result<void> r;
    switch (f.kind) {
      case motion::AxisFunc::Kind::Const:
        r = demand(a, dr::TableMode::position, f.theta0 * units::kRadToDeg);
        break;
      case motion::AxisFunc::Kind::Cycloid:
        r = demand(a, dr::TableMode::position, (f.theta0 + f.delta) * units::kRadToDeg);
        break;
      case motion::AxisFunc::Kind::Quadratic:
        r = demand(a, dr::TableMode::rate, (f.omega0 + f.alpha * (piece.t1_s - piece.t0_s)) * units::kRadToDeg);
        break;
      case motion::AxisFunc::Kind::Sine:
        break;  // track_sines()
    }
    if (!r) return fail(a, r.error());
  }
  return true;
}

void WireBench::track_sines() {
  if (next_piece_ == 0 || reads_.empty()) return;
  const motion::Piece& piece = program_.pieces[next_piece_ - 1];
  const TableRead& read = reads_.back();
  const double t_s = expect_value(program_time_s(read.t_ns), "the program's time while it is followed");
  if (t_s >= piece.t1_s) return;
  const table::AxisState now = program_.evaluate(t_s);
  const table::AxisState ahead = program_.evaluate(t_s + kTrackLookahead_s);
  for (int a = 0; a < 3; ++a) {
    const auto i = static_cast<std::size_t>(a);
    if (piece.axis[i].kind != motion::AxisFunc::Kind::Sine) continue;
    const auto e = static_cast<Eigen::Index>(a);
    const double error_deg = now.angle_rad[e] * units::kRadToDeg - read.angle_deg[i];
    const double limit_dps = settings_.limits.axis[i].rate_dps;
    const double demand_dps =
        std::clamp(ahead.rate_radps[e] * units::kRadToDeg + kTrackGain_per_s * error_deg, -limit_dps, limit_dps);
    if (auto r = demand(a, dr::TableMode::rate, demand_dps); !r) {
      table_error_ = "following segment '" + piece.segment + "', " + motion::kAxisNames[i] + " axis: " + r.error().message;
      return;
    }
  }
}

void WireBench::restore_limits() {
  for (int a = 0; a < 3; ++a) {
    const auto i = static_cast<std::size_t>(a);
    if (!rate_limit_changed_[i]) continue;
    if (dev_->table->set_limits(a, dr::TableMode::rate, table_limit_setting(settings_.limits.axis[i])))
      rate_limit_changed_[i] = false;
  }
}

// Rate zero on every axis that is under control, where it is (the safe hold).
DeviceResult WireBench::stop_motion() {
  following_ = false;
  pending_.clear();
  pending_temps_.clear();
  restore_limits();
  std::string problems;
  for (int a = 0; a < 3; ++a) {
    const auto i = static_cast<std::size_t>(a);
    if (modes_[i] == dr::TableMode::off) continue;
    auto r = dev_->table->set_mode(a, dr::TableMode::rate);
    if (r) {
      modes_[i] = dr::TableMode::rate;
      r = demand(a, dr::TableMode::rate, 0.0);
    }
    if (!r) problems += std::string(problems.empty() ? "" : "; ") + motion::kAxisNames[i] + " axis: " + r.error().message;
  }
  read_table();
  if (!problems.empty()) return DeviceResult::failure(problems);  // the sequencer says what it was doing
  return DeviceResult::success();
}

// Position moves to a pose, waiting (and draining the IMU) until the table rests there.
DeviceResult WireBench::reposition(const Eigen::Vector3d& target_deg) {
  following_ = false;
  restore_limits();
  for (int a = 0; a < 3; ++a) {
    const auto i = static_cast<std::size_t>(a);
    if (modes_[i] != dr::TableMode::position) {
      if (auto r = dev_->table->set_mode(a, dr::TableMode::position); !r)
        return DeviceResult::failure(std::string(motion::kAxisNames[i]) + " axis: " + r.error().message);
      modes_[i] = dr::TableMode::position;
    }
    if (auto r = demand(a, dr::TableMode::position, target_deg[static_cast<Eigen::Index>(a)]); !r)
      return DeviceResult::failure(std::string(motion::kAxisNames[i]) + " axis: " + r.error().message);
  }
  const std::int64_t deadline_ns = dr::host_time_ns() + std::llround(settings_.home_timeout_s * units::kNsPerS);
  for (;;) {
    service(10);
    if (table_state_.connected && !table_state_.moving &&
        (table_state_.angle_deg - target_deg).cwiseAbs().maxCoeff() < kAtTarget_deg)
      return DeviceResult::success();
    if (!table_state_.fault.empty()) return DeviceResult::failure("table fault while moving: " + table_state_.fault);
    if (dr::host_time_ns() > deadline_ns) {
      char text[200];
      std::snprintf(text, sizeof text, "the table did not reach [%.4f, %.4f, %.4f] deg within %.0f s", target_deg[0],
                    target_deg[1], target_deg[2], settings_.home_timeout_s);
      return DeviceResult::failure(text);
    }
  }
}

}  // namespace imucal::daemon
