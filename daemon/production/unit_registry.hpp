// The registry of units (GET /api/imus, docs/api.md "Units"): what the registry holds about each
// IMU a campaign named (campaign.imu; Registry::unit_campaigns, every stand's of a lab), as JSON
// and as a CSV history, each calibration naming its stand. Pure functions of campaign rows, so the
// rules of what counts as a calibration live here once.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/db/daemon_db.hpp"
#include "daemon/production/acceptance.hpp"

namespace imucal::daemon {

// A run is one of its unit's calibrations when it ended with a model and either ran its whole
// program or an operator accepted it (POST /api/campaigns/{id}/accept).
bool counts_as_calibration(const CampaignRow& row);

// Why a campaign cannot be accepted (empty: it can): only an ended partial run with a model.
std::string cannot_accept(const CampaignRow& row);

// {"complete", "accepted", "counts"} of one campaign, as every campaign reply carries them.
nlohmann::json completeness_json(const CampaignRow& row);

// A run's verdict against its part number's limits (acceptance.hpp); null when the run has not
// ended, has no model or its part number no limits.
nlohmann::json run_verdict(const CampaignRow& row, const AcceptanceLimits& limits);

// GET /api/imus from the campaigns that name a unit (oldest first); a unit passes or fails by its
// last calibration.
nlohmann::json unit_list_json(const std::vector<CampaignRow>& rows, const AcceptanceLimits& limits);
// GET /api/imus/{serial} from that unit's campaigns (oldest first): each calibration with its
// verdict and its change since the previous calibration that counts, and the unit's repeatability
// over the calibrations that count.
nlohmann::json unit_detail_json(const std::string& serial, const std::vector<CampaignRow>& rows,
                                const AcceptanceLimits& limits);
// GET /api/imus/{serial}/history.csv: one row per ended campaign with a model, one column per
// coefficient of the models (their JSON keys flattened, "gyro.bias_dph.x") and one for its sigma.
std::string unit_history_csv(const std::vector<CampaignRow>& rows);

}  // namespace imucal::daemon
