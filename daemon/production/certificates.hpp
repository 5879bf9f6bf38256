// Calibration certificates (issue 17, docs/api.md "Certificates", docs/daemon.md "Certificates"):
// numbers that never repeat on a site, and what a certificate states about the bench beside the
// campaign (its reference equipment, the site's gravity and how it was obtained).
//
// A number is PREFIX-YYYY-NNNNNN: the site's prefix (configuration), the year of issue and a
// site-wide sequence that never restarts (not even with the year): the registry's
// (registry/certificate_sequence.hpp for a stand alone, a database sequence in a lab's).
#pragma once

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"

namespace imucal::daemon {

// "LAB-2026-000123" (at least six digits).
std::string certificate_number(const std::string& prefix, int year, std::int64_t sequence);

// What a certificate states about the bench, as configured when its number is issued (kept with
// the number, so that a certificate shows the same equipment when printed again later):
//   {"devices", "simulated",
//    "reference_equipment": reference_equipment_json (reference_equipment.hpp): the table, the
//                           chamber and the gravity survey with their certificates, uncertainties
//                           and due dates, each judged on the day the campaign ended (UTC):
//                           `overdue`, it was out of calibration when it was used,
//    "gravity": {"value_mps2", "sigma_mps2", "source": "configured" | "normal_gravity", "latitude_deg", "height_m"}}
// (Certificates issued before issue 35's reference equipment lack the gravity survey, the
// uncertainties and sigma_mps2: what was issued stays as it was.)
nlohmann::json certificate_bench_json(const DaemonConfig& config, std::int64_t campaign_ended_ms);

}  // namespace imucal::daemon
