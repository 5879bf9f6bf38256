#include "daemon/subscribers/certificates.hpp"

#include <spdlog/spdlog.h>

namespace imucal::daemon {

void CertificatesSubscriber::transition(const Transition& t) {
  try {
    audit_("imucald", "campaign.transition", "campaign " + std::to_string(t.campaign),
           {{"from", to_string(t.from)}, {"to", to_string(t.to)}, {"reason", t.reason}});
    if (t.to == RunState::Done) issue_(t.campaign, "the run ended");
  } catch (const std::exception& e) {
    // Issued at its first request instead (GET /api/campaigns/{id}/certificate); the run itself is
    // unharmed.
    spdlog::error("campaign {}: no certificate at the end of the run: {}", t.campaign, e.what());
  } catch (...) {
    // Nothing may leave a subscriber: it would end the thread that changed the run's state.
    spdlog::error("campaign {}: no certificate at the end of the run: unknown error", t.campaign);
  }
}

}  // namespace imucal::daemon
