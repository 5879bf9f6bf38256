#include "daemon/devices/sim_bench.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <thread>

#include "core/number_text.hpp"
#include "core/units.hpp"
#include "sim/thermal_model.hpp"

namespace imucal::daemon {

namespace {
constexpr double kTempPeriod_s = 1.0;
}

std::shared_ptr<const sim::ThermalModel> campaign_thermal_model(const CampaignSpec& spec, double duration_s) {
  if (!thermal::thermal_of(spec.truth)) return nullptr;
  return std::make_shared<const sim::ThermalModel>(spec.chamber.profile, spec.truth, sim::ThermalConfig{}, duration_s);
}

// ------------------------------------------------------------------------------------------------
// The three device facades over the one simulated world.

class SimBench::SimTable final : public Table {
 public:
  explicit SimTable(SimBench& b) : b_(b) {}
  DeviceResult home() override {
    if (auto r = usable(); !r.ok) return r;
    b_.running_ = false;
    b_.advance_world(b_.settings_.home_time_s);
    b_.held_deg_.setZero();
    b_.homed_ = true;
    return DeviceResult::success();
  }
  DeviceResult close_interlock() override {
    if (auto r = usable(); !r.ok) return r;
    b_.interlock_closed_ = true;
    return DeviceResult::success();
  }
  DeviceResult open_interlock() override {
    if (!b_.interlock_closed_) return DeviceResult::success();
    if (b_.fault_active(SimFault::Kind::Disconnect, "table"))
      return DeviceResult::failure("table does not answer (simulated disconnect)");
    if (b_.running_) return DeviceResult::failure("table is moving; stop it before opening the interlock");
    b_.interlock_closed_ = false;
    return DeviceResult::success();
  }
  DeviceResult stop() override {
    if (b_.running_) {
      b_.held_deg_ = b_.current_angles_deg();
      b_.running_ = false;
    }
    // A disconnected table's own controller stops it too (loss of the command link trips the
    // drives); report the disconnect so that the sequencer records it.
    if (b_.fault_active(SimFault::Kind::Disconnect, "table"))
      return DeviceResult::failure("table does not answer (simulated disconnect); its controller stopped it");
    return DeviceResult::success();
  }
  DeviceResult start_program_at(double t_s) override {
    if (auto r = usable(); !r.ok) return r;
    if (!b_.homed_) return DeviceResult::failure("table is not homed");
    if (!b_.interlock_closed_) return DeviceResult::failure("table interlock is open");
    const std::int64_t target = b_.frames_up_to(t_s);
    const Eigen::Vector3d from_deg = b_.current_angles_deg();
    b_.position_simulator(target);
    const double t_start_s = static_cast<double>(target) * b_.dt_s_;
    const Eigen::Vector3d to_deg = b_.program_.evaluate(t_start_s).angle_rad * units::kRadToDeg;
    // Repositioning takes device time; no frames are recorded while it happens.
    const double move_s = (to_deg - from_deg).cwiseAbs().maxCoeff() / b_.settings_.reposition_rate_dps;
    if (move_s > 0.0) b_.advance_world(move_s + 1.0);
    b_.held_deg_ = to_deg;
    b_.next_temp_t_s_ = std::ceil(t_start_s / kTempPeriod_s) * kTempPeriod_s;
    b_.running_ = true;
    return DeviceResult::success();
  }
  TableState state() const override {
    TableState s;
    s.angle_deg = b_.current_angles_deg();
    if (b_.running_) s.rate_dps = b_.program_.evaluate(b_.program_time_s()).rate_radps * units::kRadToDeg;
    s.homed = b_.homed_;
    s.interlock_closed = b_.interlock_closed_;
    s.moving = b_.running_;
    s.connected = !b_.fault_active(SimFault::Kind::Disconnect, "table");
    if (b_.fault_active(SimFault::Kind::TableFault)) s.fault = "drive fault (simulated)";
    return s;
  }

 private:
  DeviceResult usable() const {
    if (b_.fault_active(SimFault::Kind::Disconnect, "table"))
      return DeviceResult::failure("table does not answer (simulated disconnect)");
    if (b_.fault_active(SimFault::Kind::TableFault)) return DeviceResult::failure("table drive fault (simulated)");
    return DeviceResult::success();
  }
  SimBench& b_;
};

class SimBench::SimChamber final : public Chamber {
 public:
  explicit SimChamber(SimBench& b) : b_(b) {}
  DeviceResult set_setpoint(double setpoint_C) override {
    if (b_.fault_active(SimFault::Kind::Disconnect, "chamber"))
      return DeviceResult::failure("chamber does not answer (simulated disconnect)");
    b_.setpoint_C_ = setpoint_C;
    return DeviceResult::success();
  }
  ChamberState state() const override {
    ChamberState s;
    s.temperature_C = (b_.settings_.thermal ? b_.settings_.thermal->state(b_.thermal_time_s()).air_C : b_.chamber_C_) +
                      b_.chamber_offset_C();
    s.setpoint_C = b_.setpoint_C_;
    s.connected = !b_.fault_active(SimFault::Kind::Disconnect, "chamber");
    return s;
  }

 private:
  SimBench& b_;
};

class SimBench::SimImu final : public Imu {
 public:
  explicit SimImu(SimBench& b) : b_(b) {}
  DeviceResult read(FrameBatch& out, std::int64_t until_t_ns) override { return b_.read(out, until_t_ns); }
  ImuState state() const override { return {!b_.fault_active(SimFault::Kind::Disconnect, "imu")}; }
  RecordingMeta recording_meta() const override { return b_.sim_->meta(); }

 private:
  SimBench& b_;
};

// ------------------------------------------------------------------------------------------------

SimBench::SimBench(const motion::Program& program, const ImuModel& truth, const SimBenchSettings& settings)
    : program_(program),
      truth_(truth),
      settings_(settings),
      dt_s_(1.0 / settings.sim.rate_hz),
      chamber_C_(settings.chamber_start_C),
      setpoint_C_(settings.chamber_start_C) {
  // A read covers at most a quarter second of device time, so that the suspenders see a
  // condition while it lasts; paced, also at most about 20 ms of wall time, so that commands and
  // telemetry stay responsive.
  double frames = settings.sim.rate_hz * 0.25;
  if (settings.time_scale > 0.0) frames = std::min(frames, settings.sim.rate_hz * settings.time_scale * 0.02);
  batch_frames_ = static_cast<std::int64_t>(std::clamp(frames, 1.0, 4096.0));
  if (settings_.thermal) settings_.sim.thermal = settings_.thermal.get();
  sim_ = std::make_unique<sim::Simulator>(program_, truth_, settings_.sim);
  for (const SimFault& f : settings.faults) {
    ActiveFault af;
    af.fault = f;
    faults_.push_back(af);
  }
  pace_wall0_ = std::chrono::steady_clock::now();
  table_ = std::make_unique<SimTable>(*this);
  chamber_ = std::make_unique<SimChamber>(*this);
  imu_ = std::make_unique<SimImu>(*this);
}

SimBench::~SimBench() {
  // A disk_full fault still in force when the run ends (or the bench is dropped) gives the space back.
  for (const auto& f : faults_)
    if (f.fault.kind == SimFault::Kind::DiskFull && f.fired && !f.over && settings_.disk) settings_.disk.set_full(false);
}

void SimBench::resuming_after(double t_s) {
  resumed_after_s_ = t_s;
  for (auto& f : faults_)
    if (!f.fired && f.fault.at_s <= t_s) {
      f.fired = true;
      f.fired_world_s = -std::numeric_limits<double>::infinity();  // long over
      f.over = true;
    }
}

void SimBench::fire_fault(ActiveFault& af) {
  af.fired = true;
  af.fired_world_s = world_s_;
  af.corrupt_left = af.fault.kind == SimFault::Kind::ImuCorrupt ? af.fault.frames : 0;
  af.drop_left = af.fault.kind == SimFault::Kind::ImuDrop ? af.fault.frames : 0;
  // The daemon's disk (every SQLite write of the process: settings_.disk, storage's switch) until the fault's
  // duration of device time has passed: a full disk at a program time, for drills and the chaos soak.
  if (af.fault.kind == SimFault::Kind::DiskFull && settings_.disk) {
    af.refused_at_fire = settings_.disk.refused_writes();
    settings_.disk.set_full(true);
  }
}

// A full disk is met by the next write, which comes up to a commit interval of wall time later:
// in accelerated time the fault's duration would be over before anything wrote. It lasts
// duration_s of device time from the first write it refused.
void SimBench::expire_faults() {
  for (auto& f : faults_) {
    if (f.fault.kind != SimFault::Kind::DiskFull || !f.fired || f.over || !settings_.disk) continue;
    if (!f.met_world_s) {
      if (settings_.disk.refused_writes() == f.refused_at_fire) continue;
      f.met_world_s = world_s_;
    }
    if (world_s_ < *f.met_world_s + f.fault.duration_s) continue;
    f.over = true;
    settings_.disk.set_full(false);
  }
}

Table& SimBench::table() { return *table_; }
Chamber& SimBench::chamber() { return *chamber_; }
Imu& SimBench::imu() { return *imu_; }

std::string SimBench::describe() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "simulated bench (in-process, %.0f Hz, seed %llu, time scale %s)",
                settings_.sim.rate_hz, static_cast<unsigned long long>(settings_.sim.seed),
                settings_.time_scale <= 0 ? "as fast as possible" : (number_text(settings_.time_scale) + "x").c_str());
  return buf;
}

double SimBench::program_time_s() const { return static_cast<double>(sim_pos_) * dt_s_; }

double SimBench::thermal_time_s() const {
  return sim_pos_ == 0 && resumed_after_s_ ? *resumed_after_s_ : program_time_s();
}

bool SimBench::fault_active(SimFault::Kind kind, const char* device) const {
  for (const auto& f : faults_) {
    if (f.fault.kind != kind || !f.active(world_s_)) continue;
    if (device == nullptr || f.fault.device == device) return true;
  }
  return false;
}

double SimBench::chamber_offset_C() const {
  double offset_C = 0.0;
  for (const auto& f : faults_)
    if (f.fault.kind == SimFault::Kind::ChamberOffset && f.active(world_s_)) offset_C += f.fault.offset_C;
  return offset_C;
}

bool SimBench::table_blocked() const {
  return fault_active(SimFault::Kind::Disconnect, "table") || fault_active(SimFault::Kind::TableFault);
}

Eigen::Vector3d SimBench::current_angles_deg() const {
  if (!running_) return held_deg_;
  return program_.evaluate(program_time_s()).angle_rad * units::kRadToDeg;
}

std::int64_t SimBench::frames_up_to(double t_s) const {
  const auto t_ns = std::llround(t_s * units::kNsPerS);
  const double rate = settings_.sim.rate_hz;
  auto frame_t_ns = [&](std::int64_t p) { return std::llround(static_cast<double>(p) * units::kNsPerS / rate); };
  auto p = static_cast<std::int64_t>(std::floor(t_s * rate));
  p = std::clamp<std::int64_t>(p, 0, sim_->frame_count());
  while (p < sim_->frame_count() && frame_t_ns(p + 1) <= t_ns) ++p;
  while (p > 0 && frame_t_ns(p) > t_ns) --p;
  return p;
}

void SimBench::position_simulator(std::int64_t frame_index) {
  if (snapshot_ && snapshot_pos_ == frame_index) {
    sim_ = std::make_unique<sim::Simulator>(*snapshot_);
    sim_pos_ = frame_index;
  } else {
    if (sim_pos_ > frame_index) {
      // Behind us and no copy: run the simulation again from its start (after a restart).
      sim_ = std::make_unique<sim::Simulator>(program_, truth_, settings_.sim);
      sim_pos_ = 0;
    }
    ImuFrame f;
    while (sim_pos_ < frame_index && sim_->next(f)) {
      ++sim_pos_;
      if ((sim_pos_ & 0xFFFF) == 0) (void)sim_->take_temps();
    }
    snapshot_ = std::make_unique<sim::Simulator>(*sim_);
    snapshot_pos_ = sim_pos_;
  }
  (void)sim_->take_temps();  // the bench makes its own temperatures from the chamber model
}

void SimBench::pace() {
  if (settings_.time_scale <= 0.0) return;
  using namespace std::chrono;
  const auto now = steady_clock::now();
  const auto target = pace_wall0_ + duration_cast<steady_clock::duration>(
                                        duration<double>((world_s_ - pace_world0_) / settings_.time_scale));
  if (target > now) {
    std::this_thread::sleep_until(target);
  } else if (now - target > milliseconds(500)) {
    // Fell behind (a loaded machine, a slow consumer): carry on from here instead of rushing.
    pace_wall0_ = now;
    pace_world0_ = world_s_;
  }
}

void SimBench::advance_world(double seconds) {
  if (seconds > 0.0) {
    world_s_ += seconds;
    chamber_C_ += (setpoint_C_ - chamber_C_) * (1.0 - std::exp(-seconds / settings_.chamber_tau_s));
  }
  expire_faults();
  pace();
}

void SimBench::wait(double seconds) { advance_world(seconds); }

void SimBench::log_temperatures_until(double t_s, FrameBatch& out) {
  while (next_temp_t_s_ <= t_s) {
    TempSample ts;
    bool logged = true;
    if (settings_.thermal) {
      // The thermal model's sensors and air at this instant.
      logged = settings_.thermal->temperatures(next_temp_t_s_, ts);
    } else {
      // The IMU sits in the chamber's air; its sensors follow it closely enough for a simulation.
      ts.chamber_C = chamber_C_;
      ts.gyro_C.setConstant(chamber_C_);
      ts.accel_C.setConstant(chamber_C_);
    }
    ts.chamber_C += chamber_offset_C();  // the chamber reading's faults
    ts.t_ns = std::llround(next_temp_t_s_ * units::kNsPerS);
    ts.chamber_setpoint_C = setpoint_C_;
    if (logged) out.temps.push_back(ts);
    next_temp_t_s_ += kTempPeriod_s;
  }
}

// Every active fault with frames `left` counts the frame off (two overlapping faults both count it).
bool SimBench::fault_takes_frame(std::int64_t ActiveFault::*left) {
  bool taken = false;
  for (auto& af : faults_) {
    if (af.*left > 0) {
      --(af.*left);
      taken = true;
    }
  }
  return taken;
}

DeviceResult SimBench::read(FrameBatch& out, std::int64_t until_t_ns) {
  out.clear();
  // Idle reads (nothing produced) let a little device time pass, so that a caller polling in a loop
  // sees timeouts expire at their real resolution.
  const double idle_s = std::min(0.1, static_cast<double>(batch_frames_) * dt_s_);
  if (fault_active(SimFault::Kind::Disconnect, "imu")) {
    advance_world(idle_s);
    return DeviceResult::failure("IMU does not answer (simulated disconnect)");
  }
  if (!running_ || table_blocked()) {
    if (running_) {
      held_deg_ = current_angles_deg();
      running_ = false;
    }
    advance_world(idle_s);
    return DeviceResult::success();
  }
  const double world0 = world_s_;
  const double rate = settings_.sim.rate_hz;
  ImuFrame f;
  for (std::int64_t n = 0; n < batch_frames_; ++n) {
    const auto next_t_ns = std::llround(static_cast<double>(sim_pos_ + 1) * units::kNsPerS / rate);
    if (next_t_ns > until_t_ns) break;
    if (!sim_->next(f)) {
      held_deg_ = current_angles_deg();
      running_ = false;
      break;
    }
    ++sim_pos_;
    world_s_ += dt_s_;
    const double t_s = static_cast<double>(f.t_ns) / units::kNsPerS;
    for (auto& af : faults_) {
      if (!af.fired && t_s >= af.fault.at_s) fire_fault(af);
    }
    log_temperatures_until(t_s, out);
    if (table_blocked()) {
      held_deg_ = current_angles_deg();
      running_ = false;
      break;
    }
    if (fault_active(SimFault::Kind::ImuDropout)) continue;
    if (fault_takes_frame(&ActiveFault::drop_left)) continue;  // lost on the way: a gap
    if (fault_takes_frame(&ActiveFault::corrupt_left)) f.dtheta_rad.x() = std::numeric_limits<double>::quiet_NaN();
    out.frames.push_back(f);
  }
  // The chamber and the pacing move by the batch's device time.
  const double elapsed = world_s_ - world0;
  world_s_ = world0;
  advance_world(elapsed);
  return DeviceResult::success();
}

}  // namespace imucal::daemon
