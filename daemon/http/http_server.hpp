// The HTTP/WebSocket front of imucald (Boost.Beast, kept out of this header): one session object
// per connection on its own strand, body and header limits and timeouts on every read, the API
// (api.hpp) and the static UI files, and the live WebSocket /api/live with a bounded queue per
// client (the oldest messages are dropped when a client reads too slowly; nothing ever waits for
// a client).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"
#include "daemon/http/api.hpp"
#include "daemon/http/static_files.hpp"
#include "daemon/sequencer/sequencer.hpp"

namespace imucal::daemon {

class HttpServer {
 public:
  HttpServer(const HttpConfig& config, Api& api, Sequencer& sequencer, const StaticFiles& files);
  ~HttpServer();
  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // Binds, listens and starts the threads. Throws std::runtime_error when the address is taken.
  void start(const std::string& host, std::uint16_t port);
  std::uint16_t port() const;
  // Sends an event to every live client (thread-safe; adds seq and t).
  void broadcast_event(const nlohmann::json& event);
  // Stops accepting, closes every connection and ends the threads (idempotent).
  void stop();

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace imucal::daemon
