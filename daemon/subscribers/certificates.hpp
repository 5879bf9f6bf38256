// The certificates' subscriber: every transition of a run written to the audit trail
// (campaign.transition), and a run that ends done issued its certificate ("the run ended"). The
// audit trail and the issuing are handed in as functions: they live in the registry and in
// production (CertificateIssuer), which the subscribers do not reach (docs/ARCHITECTURE.md).
//
// Subscribed by the service after the sequencer's own subscribers: the service database has
// stored the transition when the certificate reads the run. Called on the thread that made the
// change; it changes no run's state (the sequencer's rule for subscribers), and never throws.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/run/documents.hpp"

namespace imucal::daemon {

class CertificatesSubscriber final : public RunSubscriber {
 public:
  // AuditTrail::append: (actor, action, subject, details); never throws.
  using Audit = std::function<void(const std::string& actor, const std::string& action, const std::string& subject,
                                   const nlohmann::json& details)>;
  // CertificateIssuer::issue: (campaign, reason); throws when no number can be taken.
  using Issue = std::function<void(std::int64_t campaign, const std::string& reason)>;

  CertificatesSubscriber(Audit audit, Issue issue) : audit_(std::move(audit)), issue_(std::move(issue)) {}

  void transition(const Transition& transition) override;

 private:
  Audit audit_;
  Issue issue_;
};

}  // namespace imucal::daemon
