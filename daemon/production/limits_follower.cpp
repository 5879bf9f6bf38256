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

void LimitsFollower::follow() {
  std::lock_guard lock(mutex_);
  try {
    if (!followed_)
      if (const auto text = db_.setting(kFollowedSetting)) {
        nlohmann::json stored = nlohmann::json::parse(*text, nullptr, false);
        if (!stored.is_discarded()) followed_ = std::move(stored);  // damaged: followed again from none
      }
    const nlohmann::json now = document_();
    if (followed_ && *followed_ == now) return;
    std::optional<std::set<std::string>> changed;
    if (followed_) changed = changed_part_numbers(*followed_, now);
    if (!changed || !changed->empty()) reissue_(changed, "acceptance limits changed in the lab's registry");
    followed_ = now;
    db_.set_setting(kFollowedSetting, now.dump());
  } catch (const std::exception& e) {
    // The registry away, the disk full: followed at a later heartbeat (reissuing again is harmless:
    // a certificate whose statement stays the same is kept).
    spdlog::warn("the acceptance limits could not be followed now: {}", e.what());
  }
}

}  // namespace imucal::daemon
