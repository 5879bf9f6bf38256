#include "daemon/production/limits_follower.hpp"

#include <spdlog/spdlog.h>

#include "daemon/production/acceptance.hpp"

namespace imucal::daemon {

void reissue_under_new_limits(Registry& registry, DaemonDb& db, CertificateIssuer& issuer,
                              const std::optional<std::set<std::string>>& changed, const std::string& reason) {
  for (const std::int64_t id : registry.campaigns_with_issued()) {  // this stand's own
    const auto row = db.campaign(id);
    if (!row || !row->imu_part_number) continue;
    if (changed && !changed->contains(*row->imu_part_number)) continue;  // its verdict cannot change
    try {
      (void)issuer.issue(id, reason);
    } catch (const std::exception& e) {
      spdlog::error("campaign {}: its certificate could not be reissued under the new limits: {}", id, e.what());
    }
  }
}

LimitsFollower::LimitsFollower(DaemonDb& db, Document document, Reissue reissue)
    : db_(db), document_(std::move(document)), reissue_(std::move(reissue)) {}

nlohmann::json replace_limits(LimitsFile& limits, const AuditTrail& audit, Registry& registry, DaemonDb& db,
                              CertificateIssuer& issuer, const nlohmann::json& document, const std::string& actor) {
  const nlohmann::json before = limits.document();
  limits.replace(document, actor);
  const nlohmann::json after = limits.document();
  spdlog::info("acceptance limits replaced by {} ({} part numbers)", actor, limits.current().parts.size());
  audit.append(actor, "limits.replaced", "limits", {{"before", before}, {"after", after}});
  // Only units of the part numbers whose limits changed can have a new verdict (this runs on an
  // HTTP thread). The lab's other stands reissue theirs when their followers see the new limits.
  reissue_under_new_limits(registry, db, issuer, changed_part_numbers(before, after), "acceptance limits changed by " + actor);
  try {
    LimitsFollower::record_followed(db, after);
  } catch (const std::exception& e) {
    spdlog::warn("the new limits could not be recorded as followed ({}): the next heartbeat looks at them again", e.what());
  }
  return after;
}

void LimitsFollower::record_followed(DaemonDb& db, const nlohmann::json& document) {
  db.set_setting(kFollowedSetting, document.dump());
}

void LimitsFollower::follow() {
  std::lock_guard lock(mutex_);
  try {
    // Read at each beat: the stand's own PUT records what it reissued for (replace_limits).
    if (const auto text = db_.setting(kFollowedSetting)) {
      nlohmann::json stored = nlohmann::json::parse(*text, nullptr, false);
      if (!stored.is_discarded()) followed_ = std::move(stored);  // damaged: the one in memory, if any
    }
    const nlohmann::json now = document_();
    if (followed_ && *followed_ == now) return;
    std::optional<std::set<std::string>> changed;
    if (followed_) changed = changed_part_numbers(*followed_, now);
    if (!changed || !changed->empty()) reissue_(changed, "acceptance limits changed in the lab's registry");
    followed_ = now;
    record_followed(db_, now);
  } catch (const std::exception& e) {
    // The registry away, the disk full: followed at a later heartbeat (reissuing again is harmless:
    // a certificate whose statement stays the same is kept).
    spdlog::warn("the acceptance limits could not be followed now: {}", e.what());
  }
}

}  // namespace imucal::daemon
