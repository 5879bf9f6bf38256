// Certificates follow the lab's acceptance limits (issue 38). A certificate states its unit's
// verdict under the limits in force; when a part number's limits change, each stand supersedes
// its own certificates in force of that part number whose verdict changes (the issuer compares
// what they state: one whose statement stays the same is kept). The limits are one document for
// every stand of a lab: the stand that puts new ones reissues at once (PUT /api/limits), every
// other stand when its next heartbeat sees the document changed, and a stand that was off
// meanwhile at its first heartbeat.
#pragma once

#include <functional>
#include <mutex>
#include <optional>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/db/daemon_db.hpp"
#include "daemon/production/certificate_issuer.hpp"
#include "daemon/registry/registry.hpp"

namespace imucal::daemon {

// This stand's certificates in force of the part numbers `changed` (none: every part number)
// issued again with `reason`: superseded where what they state changes. A failure is logged per
// campaign; the others go on.
void reissue_under_new_limits(Registry& registry, DaemonDb& db, CertificateIssuer& issuer,
                              const std::optional<std::set<std::string>>& changed, const std::string& reason);

class LimitsFollower {
 public:
  // `document`: the limits in force now (LimitsFile::document, read from the registry).
  using Document = std::function<nlohmann::json()>;
  LimitsFollower(Registry& registry, DaemonDb& db, CertificateIssuer& issuer, Document document);

  // Compares the document in force with the one followed last; when it changed (or at the first
  // call, whatever happened while this stand was off), reissues under it. Never throws.
  void follow();

 private:
  Registry& registry_;
  DaemonDb& db_;
  CertificateIssuer& issuer_;
  Document document_;
  std::mutex mutex_;
  std::optional<nlohmann::json> followed_;
};

}  // namespace imucal::daemon
