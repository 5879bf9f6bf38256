// Helpers of the daemon tests: a scratch data directory, a minimal blocking HTTP/1.1 client on
// raw sockets (one request per connection), waiting for a campaign state, and the frames a run
// file holds.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/recording.hpp"
#include "storage/run_db.hpp"
#include "tests/test_paths.hpp"

namespace imucal::daemontest {

using nlohmann::json;

inline std::string scratch_dir(const std::string& name) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string dir = imucaltest::test_tmp_dir() + "/daemon/" + name + "-" +
                    (info != nullptr ? std::string(info->name()) : std::string("x")) + "-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

struct HttpResult {
  int status = 0;
  std::map<std::string, std::string> headers;  // lower-case names
  std::string body;
  json json_body() const {
    try {
      return json::parse(body);
    } catch (...) {
      return json();
    }
  }
  // A sign-in's session cookie as a browser sends it back ("imucal_session=..."), without the
  // attributes of its Set-Cookie.
  std::string session_cookie() const {
    const std::string& set_cookie = headers.at("set-cookie");
    return set_cookie.substr(0, set_cookie.find(';'));
  }
};

// One request, `Connection: close`, reads until the server closes.
inline HttpResult http_request(std::uint16_t port, const std::string& method, const std::string& target,
                               const std::string& body = "", const std::map<std::string, std::string>& headers = {}) {
  HttpResult r;
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return r;
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return r;
  }
  timeval tv{30, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  std::string req = method + " " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n";
  for (const auto& [k, v] : headers) req += k + ": " + v + "\r\n";
  if (!body.empty() || method == "POST") {
    if (headers.count("Content-Type") == 0 && !body.empty()) req += "Content-Type: application/json\r\n";
    req += "Content-Length: " + std::to_string(body.size()) + "\r\n";
  }
  req += "\r\n" + body;
  std::size_t sent = 0;
  while (sent < req.size()) {
    const auto n = ::send(fd, req.data() + sent, req.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) break;
    sent += static_cast<std::size_t>(n);
  }
  std::string raw;
  char buf[65536];
  for (;;) {
    const auto n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    raw.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  const auto head_end = raw.find("\r\n\r\n");
  if (head_end == std::string::npos || raw.size() < 12) return r;
  r.status = std::stoi(raw.substr(9, 3));
  std::size_t pos = raw.find("\r\n") + 2;
  while (pos < head_end) {
    const auto end = raw.find("\r\n", pos);
    const std::string line = raw.substr(pos, end - pos);
    const auto colon = line.find(':');
    if (colon != std::string::npos) {
      std::string name = line.substr(0, colon);
      for (auto& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      r.headers[name] = line.substr(colon + 2);
    }
    pos = end + 2;
  }
  r.body = raw.substr(head_end + 4);
  return r;
}

// A client with a bearer token (empty: none).
struct Client {
  std::uint16_t port = 0;
  std::string token;
  std::map<std::string, std::string> auth() const {
    if (token.empty()) return {};
    return {{"Authorization", "Bearer " + token}};
  }
  HttpResult get(const std::string& target) const { return http_request(port, "GET", target, "", auth()); }
  HttpResult post(const std::string& target, const std::string& body = "") const {
    return http_request(port, "POST", target, body, auth());
  }
  json get_json(const std::string& target) const { return get(target).json_body(); }
  // A result computed as a job (allan, thermal, evaluation): 202 while it computes, then the answer.
  HttpResult get_computed(const std::string& target, double timeout_s = 600.0) const {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    HttpResult r = get(target);
    while (r.status == 202 && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      r = get(target);
    }
    return r;
  }
  // Polls GET /api/campaigns/{id} until `pred` holds or the timeout passes; returns the last body.
  json wait_for(std::int64_t id, const std::function<bool(const json&)>& pred, double timeout_s = 60.0) const {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    json last;
    while (std::chrono::steady_clock::now() < deadline) {
      last = get_json("/api/campaigns/" + std::to_string(id));
      if (last.is_object() && pred(last)) return last;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ADD_FAILURE() << "timed out waiting on campaign " << id << "; last: " << last.dump().substr(0, 2000);
    return last;
  }
  json wait_state(std::int64_t id, const std::string& state, double timeout_s = 60.0) const {
    return wait_for(id, [&](const json& c) { return c.value("state", "") == state; }, timeout_s);
  }
  // POST /api/campaigns, then its start: the campaign's id, or 0 with the refusal recorded.
  std::int64_t post_and_start(const json& campaign) const {
    const HttpResult posted = post("/api/campaigns", campaign.dump());
    EXPECT_EQ(posted.status, 201) << posted.body;
    if (posted.status != 201) return 0;
    const auto id = posted.json_body().at("id").get<std::int64_t>();
    const HttpResult started = post("/api/campaigns/" + std::to_string(id) + "/start");
    EXPECT_EQ(started.status, 200) << started.body;
    return started.status == 200 ? id : 0;
  }
};

inline std::vector<ImuFrame> run_frames(const std::string& path) {
  const auto db = storage::RunDb::open(path, storage::OpenMode::Read);
  return db.read_frames();
}

// Bit-for-bit equality of two frames.
inline bool same_frame(const ImuFrame& a, const ImuFrame& b) {
  return a.t_ns == b.t_ns && a.dtheta_rad == b.dtheta_rad && a.dv_mps == b.dv_mps && a.table_deg == b.table_deg;
}

inline bool has_event(const json& campaign, const std::string& kind, const std::string& reason_part = "") {
  for (const auto& e : campaign.at("events"))
    if (e.at("kind") == kind && e.at("reason").get<std::string>().find(reason_part) != std::string::npos) return true;
  return false;
}

inline bool has_transition(const json& campaign, const std::string& from, const std::string& to) {
  for (const auto& t : campaign.at("transitions"))
    if (t.at("from") == from && t.at("to") == to) return true;
  return false;
}

}  // namespace imucal::daemontest
