// Certificates follow the lab's acceptance limits (issue 38). A certificate states its unit's
// verdict under the limits in force; when a part number's limits change, each stand supersedes
// its own certificates in force of that part number whose verdict changes (the issuer compares
// what they state: one whose statement stays the same is kept). The limits are one document for
// every stand of a lab: the stand that puts new ones reissues at once (PUT /api/limits), every
// other stand when its next heartbeat sees the document changed, and a stand that was off
// meanwhile at its first heartbeat. The document followed last is kept in the stand's database: a
// restart under the same limits reissues nothing (each reissue renders every certificate in force),
// nor does a beat after the stand's own PUT (replace_limits records what it reissued for).
#pragma once

#include <functional>
#include <mutex>
#include <optional>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/db/daemon_db.hpp"
#include "daemon/production/certificate_issuer.hpp"
#include "daemon/production/limits_file.hpp"
#include "daemon/registry/audit_trail.hpp"
#include "daemon/registry/registry.hpp"

namespace imucal::daemon {

// This stand's certificates in force of the part numbers `changed` (none: every part number)
// issued again with `reason`: superseded where what they state changes. A failure is logged per
// campaign; the others go on.
void reissue_under_new_limits(Registry& registry, DaemonDb& db, CertificateIssuer& issuer,
                              const std::optional<std::set<std::string>>& changed, const std::string& reason);

// PUT /api/limits: `document` put by `actor` in place of the limits in force (throws
// std::invalid_argument naming the entry at fault, changing nothing; a failure of the store: its
// error), audited, this stand's certificates whose verdict it changes superseded at once, and the
// document recorded as followed. Returns the limits in force after it.
nlohmann::json replace_limits(LimitsFile& limits, const AuditTrail& audit, Registry& registry, DaemonDb& db,
                              CertificateIssuer& issuer, const nlohmann::json& document, const std::string& actor);

class LimitsFollower {
 public:
  // `document`: the limits in force now (LimitsFile::document, read from the registry).
  using Document = std::function<nlohmann::json()>;
  // `reissue`: reissue_under_new_limits with this stand's registry, database and issuer.
  using Reissue = std::function<void(const std::optional<std::set<std::string>>& changed, const std::string& reason)>;
  LimitsFollower(DaemonDb& db, Document document, Reissue reissue);

  // Compares the document in force with the one followed last (in the stand's database; none on a
  // stand that never followed one); when it changed, reissues the part numbers whose limits changed
  // (every one when none was followed). Never throws: a failure is followed at the next call.
  void follow();
  // Records `document` as followed: this stand has reissued under it (replace_limits). Throws
  // what the database throws.
  static void record_followed(DaemonDb& db, const nlohmann::json& document);

  static constexpr const char* kFollowedSetting = "limits_followed";  // DaemonDb setting: the JSON text

 private:
  DaemonDb& db_;
  Document document_;
  Reissue reissue_;
  std::mutex mutex_;
  std::optional<nlohmann::json> followed_;  // while the database cannot say (read at each call)
};

}  // namespace imucal::daemon
