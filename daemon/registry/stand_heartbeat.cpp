#include "daemon/registry/stand_heartbeat.hpp"

#include <utility>

#include <spdlog/spdlog.h>

namespace imucal::daemon {

StandHeartbeat::StandHeartbeat(Registry& registry, StandRow identity, std::chrono::milliseconds period, State state)
    : registry_(registry), identity_(std::move(identity)), period_(period), state_(std::move(state)) {
  identity_.heartbeat_ms = period_.count();
  thread_ = std::thread([this] { loop(); });
}

StandHeartbeat::~StandHeartbeat() { stop(); }

void StandHeartbeat::stop() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void StandHeartbeat::loop() {
  std::unique_lock lock(mutex_);
  while (!stopping_) {
    lock.unlock();
    beat();
    lock.lock();
    wake_.wait_for(lock, period_, [this] { return stopping_; });
  }
}

void StandHeartbeat::beat() {
  try {
    const std::string state = state_().dump();
    const std::int64_t now = now_unix_ms();
    if (registered_ && registry_.report_stand_state(identity_.name, state, now)) {
      failing_ = false;
      return;
    }
    if (registered_) spdlog::warn("registry: stand '{}' was not registered there any more: registered again", identity_.name);
    StandRow row = identity_;
    row.registered_ms = now;
    row.last_seen_ms = now;
    row.state_json = state;
    registry_.register_stand(row);
    if (!registered_) spdlog::info("registry: stand '{}' registered ({}, {})", row.name, row.url, row.version);
    registered_ = true;
    failing_ = false;
  } catch (const std::exception& e) {
    failed(e);
  }
}

// The next beat tries again (a registration not made is made then).
void StandHeartbeat::failed(const std::exception& e) {
  if (!failing_)
    spdlog::warn("registry: stand '{}' cannot report its state (tried again every {} ms): {}", identity_.name,
                 period_.count(), e.what());
  failing_ = true;
}

}  // namespace imucal::daemon
