// The device set a campaign's run drives, as the configuration names it (`devices`: sim, sim-wire
// or real): the one place that chooses and sets up a bench, so the run loop only drives one.
#pragma once

#include <memory>

#include "daemon/campaign/campaign.hpp"
#include "daemon/config/config.hpp"
#include "daemon/devices/devices.hpp"
#include "motion_programs/program.hpp"

namespace imucal::daemon {

// A bench for `spec`'s run of `program`: the in-process simulated one, the simulated devices over
// the wire, or the real devices at the configured addresses. `disk`: what a simulated disk_full
// fault fills (the caller's storage; the devices do not reach it). Throws std::runtime_error for
// devices this build or configuration cannot give.
std::unique_ptr<Bench> make_bench(const DaemonConfig& config, const CampaignSpec& spec, const motion::Program& program,
                                  const DiskFaultSwitch& disk);

}  // namespace imucal::daemon
