#include "daemon/subscribers/calibrations.hpp"

#include <spdlog/spdlog.h>

namespace imucal::daemon {

void CalibrationsSubscriber::transition(const Transition& t) {
  try {
    record_(t.campaign);
  } catch (const std::exception& e) {
    // The unit's history lacks this change until the campaign's next one; the run is unharmed.
    spdlog::error("campaign {}: its calibration could not be recorded in the registry: {}", t.campaign, e.what());
  } catch (...) {
    // Nothing may leave a subscriber: it would end the thread that changed the run's state.
    spdlog::error("campaign {}: its calibration could not be recorded in the registry: unknown error", t.campaign);
  }
}

}  // namespace imucal::daemon
