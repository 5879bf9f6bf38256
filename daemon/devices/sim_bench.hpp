// The simulated bench in-process (`--devices sim`): the physics Simulator of drivers/sim driven
// along the campaign's program, a first-order thermal chamber, and fault injection for tests and
// demonstrations (chamber drift, IMU dropouts and corrupt frames, disconnections, table faults).
// With a thermal model (a truth with a "thermal" section) the chamber air, the IMU's sensor
// temperatures and the truth's coefficients follow sim::ThermalModel along the campaign's chamber
// profile instead, as functions of program time: a redone segment sees the same temperatures, and
// while the run is held (paused, suspended) the simulated temperatures wait with it.
// Runs in accelerated simulated time: `time_scale` program seconds per wall second, or as fast as
// possible with 0.
//
// Redoing a segment is deterministic: the Simulator is restored to a copy taken at the segment's
// start (or re-run from the start after a restart), so a redone segment yields the same frames,
// bit for bit, as the first pass.
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <vector>

#include "core/imu_model.hpp"
#include "daemon/campaign/campaign.hpp"
#include "daemon/devices/devices.hpp"
#include "motion_programs/program.hpp"
#include "sim/simulator.hpp"

namespace imucal::sim {
class ThermalModel;
}

namespace imucal::daemon {

struct SimBenchSettings {
  sim::SimConfig sim;           // site, mount, rate, seed
  double time_scale = 10.0;     // 0: as fast as possible
  double chamber_tau_s = 20.0;
  double chamber_start_C = 25.0;
  double home_time_s = 5.0;
  double reposition_rate_dps = 30.0;
  std::vector<SimFault> faults;
  // Set: temperatures and thermal truth from this model (built along the campaign's chamber
  // profile over the program's duration); chamber_tau_s and chamber_start_C then do not apply.
  std::shared_ptr<const sim::ThermalModel> thermal;
  DiskFaultSwitch disk;  // what a disk_full fault fills
};

// The thermal model of a campaign on the simulated bench: along its chamber profile over
// duration_s when its truth has a "thermal" section, else none (constant temperatures).
std::shared_ptr<const sim::ThermalModel> campaign_thermal_model(const CampaignSpec& spec, double duration_s);

class SimBench final : public Bench {
 public:
  // `program` must outlive the bench.
  SimBench(const motion::Program& program, const ImuModel& truth, const SimBenchSettings& settings);
  ~SimBench() override;

  Table& table() override;
  Chamber& chamber() override;
  Imu& imu() override;
  double now_s() const override { return world_s_; }
  void wait(double seconds) override;
  bool paced_by_consumer() const override { return true; }
  double time_scale() const override { return settings_.time_scale; }
  std::string describe() const override;
  void resuming_after(double t_s) override;

  // Program time of the last frame produced.
  double program_time_s() const;
  // The program time the thermal model's chamber stands at: the last frame's, or before the first
  // frame of a resumed run the time it was resumed after.
  double thermal_time_s() const;

 private:
  class SimTable;
  class SimChamber;
  class SimImu;
  struct ActiveFault {
    SimFault fault;
    bool fired = false;
    double fired_world_s = 0.0;
    std::int64_t corrupt_left = 0;
    std::int64_t drop_left = 0;
    bool over = false;  // its effect taken back (disk_full)
    // disk_full: the refused writes when it fired, and the device time the first one was seen.
    std::int64_t refused_at_fire = 0;
    std::optional<double> met_world_s;
    bool active(double world_s) const { return fired && world_s < fired_world_s + fault.duration_s; }
  };

  void advance_world(double seconds);  // chamber, fault expiry, pacing
  void pace();
  bool fault_active(SimFault::Kind kind, const char* device = nullptr) const;
  bool table_blocked() const;
  // read()'s steps: the temperature records up to program time t_s; whether a drop or corrupt
  // fault (its frames `left`) takes this frame, counting it off.
  void log_temperatures_until(double t_s, FrameBatch& out);
  bool fault_takes_frame(std::int64_t ActiveFault::*left);
  double chamber_offset_C() const;  // what active chamber_offset faults add to the chamber's reading  // disconnected or faulted: it cannot move
  void position_simulator(std::int64_t frame_index);
  std::int64_t frames_up_to(double t_s) const;
  Eigen::Vector3d current_angles_deg() const;
  DeviceResult read(FrameBatch& out, std::int64_t until_t_ns);

  const motion::Program& program_;
  ImuModel truth_;
  SimBenchSettings settings_;
  double dt_s_;
  std::int64_t batch_frames_;

  std::unique_ptr<sim::Simulator> sim_, snapshot_;
  std::int64_t sim_pos_ = 0, snapshot_pos_ = -1;  // frames produced

  double world_s_ = 0.0;
  std::optional<double> resumed_after_s_;
  std::chrono::steady_clock::time_point pace_wall0_;
  double pace_world0_ = 0.0;

  bool homed_ = false, interlock_closed_ = false, running_ = false;
  Eigen::Vector3d held_deg_ = Eigen::Vector3d::Zero();
  double chamber_C_, setpoint_C_;
  double next_temp_t_s_ = 0.0;
  std::vector<ActiveFault> faults_;

  void fire_fault(ActiveFault& af);
  void expire_faults();

  std::unique_ptr<SimTable> table_;
  std::unique_ptr<SimChamber> chamber_;
  std::unique_ptr<SimImu> imu_;
};

}  // namespace imucal::daemon
