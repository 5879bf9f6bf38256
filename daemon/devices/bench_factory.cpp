#include "daemon/devices/bench_factory.hpp"

#include <stdexcept>

#include "daemon/devices/sim_bench.hpp"
#include "daemon/devices/wire_bench.hpp"

namespace imucal::daemon {

namespace {

std::unique_ptr<Bench> in_process_sim(const DaemonConfig& config, const CampaignSpec& spec, const motion::Program& program,
                                      const DiskFaultSwitch& disk) {
  SimBenchSettings sb;
  sb.sim.site = config.site;
  sb.sim.table = config.table_certificate;  // the simulated table moves with the certificate's errors
  sb.sim.rate_hz = spec.rate_hz;
  sb.sim.seed = spec.seed;
  sb.time_scale = spec.time_scale;
  sb.chamber_tau_s = config.sim.chamber_tau_s;
  sb.chamber_start_C = config.chamber.safe_setpoint_C;
  sb.home_time_s = config.sim.home_time_s;
  sb.faults = spec.faults;
  sb.thermal = campaign_thermal_model(spec, program.duration_s());
  sb.disk = disk;
  return std::make_unique<SimBench>(program, spec.truth, sb);
}

std::unique_ptr<Bench> over_the_wire(const DaemonConfig& config, const CampaignSpec& spec, const motion::Program& program,
                                     const DiskFaultSwitch& disk) {
  WireBenchSettings wb;
  wb.site = config.site;
  wb.rate_hz = spec.rate_hz;
  wb.limits = config.table_limits;
  if (config.devices == "real" && config.device_addresses) {
    // check_campaign refuses faults on real devices; a campaign stored under another
    // configuration is checked again before its run, so none reaches here.
    wb.table = config.table_certificate;  // the real table's certificate, into the run's meta
    return std::make_unique<WireBench>(program, wb, *config.device_addresses);
  }
  SimWireSettings sw;
  sw.faults = spec.faults;
  sw.seed = spec.seed;
  sw.truth = spec.truth;
  sw.chamber_tau_s = config.sim.chamber_tau_s;
  sw.chamber_start_C = config.chamber.safe_setpoint_C;
  sw.chamber_safe_setpoint_C = config.chamber.safe_setpoint_C;
  sw.imu_serial = spec.imu.serial;
  sw.disk = disk;
  sw.time_scale = config.sim.wire_time_scale;
  return std::make_unique<WireBench>(program, wb, sw);
}

}  // namespace

std::unique_ptr<Bench> make_bench(const DaemonConfig& config, const CampaignSpec& spec, const motion::Program& program,
                                  const DiskFaultSwitch& disk) {
  if (config.devices == "sim") return in_process_sim(config, spec, program, disk);
  if (config.devices == "sim-wire" || (config.devices == "real" && config.device_addresses))
    return over_the_wire(config, spec, program, disk);
  throw std::runtime_error("devices '" + config.devices + "' are not available in this build");
}

}  // namespace imucal::daemon
