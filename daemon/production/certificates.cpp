#include "daemon/production/certificates.hpp"

#include <cstdio>

#include "core/earth.hpp"
#include "daemon/production/reference_equipment.hpp"

namespace imucal::daemon {

using nlohmann::json;

std::string certificate_number(const std::string& prefix, int year, std::int64_t sequence) {
  char digits[32];
  std::snprintf(digits, sizeof digits, "%04d-%06lld", year, static_cast<long long>(sequence));
  return prefix + "-" + digits;
}

json certificate_bench_json(const DaemonConfig& config, std::int64_t campaign_ended_ms) {
  const bool configured = config.site.gravity_mps2.has_value();
  return {{"devices", config.devices},
          {"simulated", config.devices.rfind("sim", 0) == 0},
          // Judged on the day the run ended: out of calibration when it was used.
          {"reference_equipment", reference_equipment_json(config, utc_day(campaign_ended_ms), false)},
          {"gravity",
           {{"value_mps2", earth::site_gravity_mps2(config.site)},
            {"sigma_mps2", earth::site_gravity_sigma_mps2(config.site)},
            {"source", configured ? "configured" : "normal_gravity"},
            {"latitude_deg", config.site.latitude_deg},
            {"height_m", config.site.height_m}}}};
}

}  // namespace imucal::daemon
