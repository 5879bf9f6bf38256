// An in-process imucald (no HTTP unless asked) on a scratch data directory, driven through its API
// functions, and the reference a run must reproduce: the same program simulated straight through.
#pragma once

#include <memory>
#include <string>
#include <utility>

#include <spdlog/spdlog.h>

#include "daemon/campaign/campaign.hpp"
#include "daemon/config/password_hash.hpp"
#include "daemon/service.hpp"
#include "daemon_fixture.hpp"
#include "sim/simulator.hpp"

namespace imucal::daemontest {

inline constexpr const char* kOperatorToken = "test-operator-token-0123456789";
inline constexpr const char* kViewerToken = "test-viewer-token-0123456789";

// A truth with biases and white noise, so that a redone segment that did not continue the noise
// streams exactly would show.
inline json noisy_truth() {
  return json::parse(R"({"format": "imucal-imu-model/1", "frame": "instrument",
    "gyro": {"bias_dph": [0.05, -0.03, 0.02], "scale_pos_ppm": [20, -10, 5], "scale_neg_ppm": [25, -5, 0],
             "noise": {"arw_deg_rth": 0.0005}},
    "accel": {"bias_mps2": [1e-4, 2e-4, -1e-4], "scale_ppm": [50, -40, 30], "noise": {"vrw_mps_rth": 0.002}}})");
}

// The suite's short calibration: stage 1 on direct-short at 20 Hz (seed 7, the noisy truth) of the
// unit `imu` names; a complete model, hence a certificate at its end. time_scale 0: as fast as the
// machine goes.
inline json direct_short_calibration(const std::string& name, json imu, double time_scale = 0.0) {
  return {{"name", name},
          {"program", "direct-short"},
          {"rate_hz", 20},
          {"seed", 7},
          {"time_scale", time_scale},
          {"truth", noisy_truth()},
          {"estimators", {"direct"}},
          {"imu", std::move(imu)}};
}

inline daemon::DaemonConfig test_config(const std::string& dir) {
  daemon::DaemonConfig c;
  c.data_dir = dir;
  c.http.port = 0;
  c.operator_token = kOperatorToken;
  // One hash for every daemon of a test executable: Argon2id takes a fraction of a second by design.
  static const std::string viewer_hash = daemon::hash_password("viewer-password");
  c.users = {{"viewer", daemon::Role::Viewer, viewer_hash, kViewerToken}};
  c.log.file = "";
  c.suspenders.settle_s = 5.0;
  return c;
}

struct LocalDaemon {
  explicit LocalDaemon(const std::string& name, bool http = false,
                       const std::function<void(daemon::DaemonConfig&)>& tweak = {}) {
    spdlog::set_level(spdlog::level::warn);
    config = test_config(scratch_dir(name));
    if (tweak) tweak(config);
    service = std::make_unique<daemon::Service>(config);
    service->start(http);
  }
  ~LocalDaemon() {
    if (service) service->stop();
  }

  daemon::HttpReply call(const std::string& method, const std::string& target, const std::string& body = "",
                         const std::string& token = kOperatorToken) {
    daemon::ApiRequest r;
    r.method = method;
    r.target = target;
    r.body = body;
    r.content_type = body.empty() ? "" : "application/json";
    if (!token.empty()) r.authorization = "Bearer " + token;
    return service->api().handle(r);
  }
  json get(const std::string& target) { return json::parse(call("GET", target).body); }
  // A result computed as a job (allan, thermal, evaluation): 202 while it computes, then the answer.
  daemon::HttpReply get_computed(const std::string& target, double timeout_s = 600.0) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    daemon::HttpReply r = call("GET", target);
    while (r.status == 202 && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      r = call("GET", target);
    }
    return r;
  }
  std::int64_t post_campaign(const json& campaign) {
    const auto r = call("POST", "/api/campaigns", campaign.dump());
    EXPECT_EQ(r.status, 201) << r.body;
    return json::parse(r.body).value("id", std::int64_t{0});
  }
  int command(std::int64_t id, const std::string& cmd) {
    return call("POST", "/api/campaigns/" + std::to_string(id) + "/" + cmd).status;
  }
  json campaign(std::int64_t id) { return get("/api/campaigns/" + std::to_string(id)); }
  json wait_for(std::int64_t id, const std::function<bool(const json&)>& pred, double timeout_s = 120.0) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    json last;
    while (std::chrono::steady_clock::now() < deadline) {
      last = campaign(id);
      if (pred(last)) return last;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ADD_FAILURE() << "timed out waiting on campaign " << id << ": " << last.dump().substr(0, 3000);
    return last;
  }
  json wait_state(std::int64_t id, const std::string& state, double timeout_s = 120.0) {
    return wait_for(id, [&](const json& c) { return c.value("state", "") == state; }, timeout_s);
  }
  // The campaign's final state, once its run has given its last document to every subscriber
  // (the state is stored by the first; the certificate of a run that ended is issued by a later one).
  json wait_final(std::int64_t id, double timeout_s = 120.0) {
    json last = wait_for(id, [&](const json& c) {
      const auto s = c.value("state", "");
      return s == "done" || s == "failed" || s == "aborted" || s == "interrupted";
    }, timeout_s);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (service->sequencer().active_id() == id && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (service->sequencer().active_id() == id) ADD_FAILURE() << "campaign " << id << "'s run never ended after its state";
    return last;
  }
  std::string run_path(const json& campaign) { return config.data_dir + "/" + campaign.at("run_db").get<std::string>(); }

  daemon::DaemonConfig config;
  std::unique_ptr<daemon::Service> service;
};

// The frames of the campaign's program simulated straight through, with no interruption.
inline std::vector<ImuFrame> reference_frames(const json& stored_spec, const daemon::DaemonConfig& config) {
  const auto check = daemon::check_campaign(stored_spec, config);
  EXPECT_TRUE(check.spec.has_value());
  if (!check.spec) return {};
  const auto program = daemon::compile_campaign_program(*check.spec, config);
  sim::SimConfig cfg;
  cfg.site = config.site;
  cfg.rate_hz = check.spec->rate_hz;
  cfg.seed = check.spec->seed;
  sim::Simulator s(program, check.spec->truth, cfg);
  std::vector<ImuFrame> out;
  ImuFrame f;
  while (s.next(f)) out.push_back(f);
  return out;
}

// Every frame of the reference exactly once, bit for bit, nothing else.
inline void expect_same_frames(const std::vector<ImuFrame>& got, const std::vector<ImuFrame>& want) {
  ASSERT_EQ(got.size(), want.size());
  std::size_t mismatches = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    if (!same_frame(got[i], want[i]) && mismatches++ < 3)
      ADD_FAILURE() << "frame " << i << " differs: t " << got[i].t_ns << " vs " << want[i].t_ns;
  }
  EXPECT_EQ(mismatches, 0u);
}

}  // namespace imucal::daemontest
