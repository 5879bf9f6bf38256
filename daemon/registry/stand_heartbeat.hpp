// A stand's registration and heartbeat (issue 38, the lab overview): its own thread registers the
// stand in the registry at once, then reports its state every `period` (what it runs, its
// progress, its alarms: the function given, production/lab.hpp stand_state_json). Cheap: one
// small row updated. A registry that fails (the disk full, the lab's server away and the
// registration journaled) is logged once per spell, never thrown: the stand's runs go on.
// A report the registry does not know the stand for (its database replaced) registers it again.
// stop() (and the destructor) wakes the thread at once and joins it: no shutdown waits a period.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include <nlohmann/json.hpp>

#include "daemon/registry/registry.hpp"

namespace imucal::daemon {

class StandHeartbeat {
 public:
  using State = std::function<nlohmann::json()>;
  // `identity`: name, bench, url, version (its times and state are set here); `period` > 0.
  StandHeartbeat(Registry& registry, StandRow identity, std::chrono::milliseconds period, State state);
  ~StandHeartbeat();
  StandHeartbeat(const StandHeartbeat&) = delete;
  StandHeartbeat& operator=(const StandHeartbeat&) = delete;

  void stop();

 private:
  void loop();
  void beat();
  void failed(const std::exception& e);

  Registry& registry_;
  StandRow identity_;
  std::chrono::milliseconds period_;
  State state_;
  bool registered_ = false;  // the loop's thread only
  bool failing_ = false;     // the loop's thread only: logged once per spell of failures
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace imucal::daemon
