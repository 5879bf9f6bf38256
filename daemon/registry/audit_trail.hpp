// The audit trail as the service writes it: one rule for every writer (the HTTP layer, the
// certificates, the run's transitions, the service's start). Each entry goes through the
// service's ordered writes, so that on a full disk it waits in memory, with the time it happened,
// behind the run's own deferred writes, and is chained when space returns.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/registry/registry.hpp"

namespace imucal::daemon {

class AuditTrail {
 public:
  // The service's ordered writes (Sequencer::write_db): `what` names the write in the log, `write`
  // is done in order (at once, or later when the disk has room). Handed in because the registry
  // sits below the sequencer that owns the write queue.
  using OrderedWrite = std::function<void(const std::string& what, std::function<void()> write)>;

  AuditTrail(Registry& registry, OrderedWrite write) : registry_(registry), write_(std::move(write)) {}

  // Appends an entry; a failure is logged, never thrown at the caller: the change it records is
  // made already. `t_ms`: when it happened, when not now (a certificate's time of issue).
  void append(const std::string& actor, const std::string& action, const std::string& subject,
              const nlohmann::json& details, std::optional<std::int64_t> t_ms = std::nullopt) const;

 private:
  Registry& registry_;
  OrderedWrite write_;
};

}  // namespace imucal::daemon
