// A unit's calibration as the lab's registry keeps it (registry.hpp record_calibration): the
// campaign's row as JSON text, for the PostgreSQL table and the journal of writes waiting for it,
// and the daemon's one rule for recording a campaign's row after it changed.
#pragma once

#include <cstdint>
#include <string>

#include "daemon/db/daemon_db.hpp"
#include "daemon/registry/registry.hpp"

namespace imucal::daemon {

// The fields a unit's history reads (not the run's checkpoint, queue position or estimators'
// progress, which change while it runs); `stand` is not in it (the registry keys the row by it).
std::string campaign_row_json(const CampaignRow& row);
// Throws std::invalid_argument naming the field at fault.
CampaignRow campaign_row_from_json(const std::string& text);

// Campaign `campaign_id`'s row from this stand's database recorded in the registry when it names
// a unit (a campaign that names none is no unit's calibration); false when there was nothing to
// record. A failure of the registry propagates (the caller logs it: the campaign is unharmed).
bool record_unit_calibration(DaemonDb& db, Registry& registry, std::int64_t campaign_id);

}  // namespace imucal::daemon
