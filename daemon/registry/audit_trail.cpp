#include "daemon/registry/audit_trail.hpp"

#include <spdlog/spdlog.h>

#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

void AuditTrail::append(const std::string& actor, const std::string& action, const std::string& subject,
                        const nlohmann::json& details, std::optional<std::int64_t> when) const {
  // The time it happened, not the time a deferred write gets to it.
  const std::int64_t t_ms = when.value_or(now_unix_ms());
  try {
    write_("audit entry " + action + " " + subject + " by " + actor,
           [registry = &registry_, actor, action, subject, text = details.dump(), t_ms] {
             registry->append_audit(actor, action, subject, text, t_ms);
           });
  } catch (const std::exception& e) {
    // A trail that could not take it is said loudly, in the log.
    spdlog::error("audit trail: cannot append {} {} by {}: {}", action, subject, actor, e.what());
  }
}

}  // namespace imucal::daemon
