// Issuing certificates (issue 17, docs/api.md "Certificates"): when a run ends, when a partial run
// is accepted, when the limits change, when a run is calibrated again with a corrected g, or at
// the first request for one. Each certificate's content is frozen, hashed, signed with the lab's
// key, stored in the registry (superseding the one in force) and written to the audit trail.
#pragma once

#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"
#include "daemon/db/daemon_db.hpp"
#include "daemon/registry/audit_trail.hpp"
#include "daemon/registry/registry.hpp"
#include "signing/signing.hpp"

namespace imucal::daemon {

// Why the run has no certificate (a person's sentence), or empty when it may have one: ended,
// with a model, counting as its unit's calibration.
std::string no_certificate_because(const CampaignRow& row);

// The site as the configuration states it: GET /api/status says it, a certificate states it.
nlohmann::json site_json(const DaemonConfig& config);

class CertificateIssuer {
 public:
  // The campaign as GET /api/campaigns/{id} shows it, which a certificate states: built by the
  // HTTP layer from the sequencer (the active run's progress) and the limits in force. Handed in,
  // because production sits below both, and so that the body is built in one place.
  using CampaignDetail = std::function<nlohmann::json(const CampaignRow&)>;

  // Reads the lab's signing key (certificates.signing_key_file): a key file others can read
  // stops the start (signing::read_key_file says why and how to mend it).
  CertificateIssuer(const DaemonConfig& config, DaemonDb& db, Registry& registry, const AuditTrail& audit,
                    CampaignDetail detail);

  // Issues the campaign's certificate when it counts as a calibration (complete, or accepted) and
  // has a model: a first one, or one superseding the certificate in force when what that states
  // (the verdict under today's limits, the acceptance, the bench) is no longer what is true. Returns
  // the certificate in force afterwards (none when the run does not count), or throws
  // std::runtime_error when no number can be taken.
  std::optional<IssuedCertificateRow> issue(std::int64_t id, const std::string& reason);

  // The run was calibrated again with the site's g configured now: `store` keeps what was
  // computed, given the certificate in force, and returns the reason of the certificate that
  // supersedes it, stating the corrected g (the other statements of the bench stay as issued).
  // One step with every other issue: none reads the run half stored. Throws when the campaign has
  // no certificate in force.
  using StoreRecalibration = std::function<std::string(const IssuedCertificateRow& current)>;
  IssuedCertificateRow reissue_recalibrated(std::int64_t id, const StoreRecalibration& store);

  // The lab's key, which signs the test reports too; none when none is configured.
  const std::optional<signing::KeyPair>& signing_key() const { return signing_key_; }

 private:
  // issue()'s pieces (certificate_issuer.cpp says why they are pieces).
  // `g_corrected`: the run was calibrated again with the site's g configured now, which its
  // certificate then states.
  IssuedCertificateRow reissue(const CampaignRow& row, const IssuedCertificateRow& current, const std::string& reason,
                               bool g_corrected = false);
  IssuedCertificateRow freeze_legacy(const CampaignRow& row, const CertificateRow& legacy);
  IssuedCertificateRow numbered(std::int64_t campaign_id, const std::string& reason);
  IssuedCertificateRow store_issued(IssuedCertificateRow c, nlohmann::json content);
  // The certificate's canonical content (imucal-certificate/1) for the run as it stands now.
  nlohmann::json content(const CampaignRow& row, const std::string& bench_json);

  const DaemonConfig& config_;
  DaemonDb& db_;
  Registry& registry_;
  const AuditTrail& audit_;
  CampaignDetail detail_;
  std::optional<signing::KeyPair> signing_key_;
  std::mutex mutex_;  // a campaign's certificate is looked up and issued as one step
};

}  // namespace imucal::daemon
