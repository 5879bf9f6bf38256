// The chaos soak (issue 33, deliverable 5): faults at random seeded instants while the real imucald
// runs a campaign, kill -9 of the process on the way, and the run must end `done` with nothing
// committed lost or doubled.
//
// Part A, the overnight-style campaign: `thermal-short` with its chamber profile followed by the
// programs of `full` (direct, lever-arm, navigation, evaluate) as one campaign, on the accelerated
// in-process simulated bench (`--devices sim`, 500x real time), with every fault kind of that
// bench (IMU frames corrupted and lost, the IMU silent and disconnected, the chamber silent and
// reading off, the table's link lost and a drive fault, the disk full once) and kill -9 three
// times, each followed by a restart and `resume`. The same campaign undisturbed is the reference:
// the recording must equal it frame for frame (the simulated bench redoes a segment bit for bit),
// the temperature records too except inside the marked chamber faults, and every model
// coefficient within 0.1 of its sigma.
//
// Part C, the same campaign through the wire (`--devices sim-wire`, accelerated 200x), with the
// wire's faults, three kills and the disk full: checked on the grid and on what was committed
// before each kill, the model compared but not held to 0.1 sigma (see its comment: why).
//
// Part B, the wire level: a short program in real time on `--devices sim-wire` (the simulated
// table, chamber and IMU reached through the real drivers), with the wire's faults (IMU samples
// corrupted on the link and lost, the IMU silent for seconds, Modbus timeouts, a chamber that
// stops answering, the table's connection dropped) and one kill -9. Real time is not reproducible
// frame for frame, so the check is the grid: every instant once, none lost, none doubled, and
// every frame committed before the kill unchanged.
//
// IMUCAL_CHAOS_SEED overrides the seed (printed with every failure); IMUCAL_CHAOS_RATE_HZ part A's
// rate; IMUCAL_CHAOS_WIRE_SCALE part C's time scale. bench/README.md has the command that prints
// the soak's figures.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "core/number_text.hpp"
#include "service_fixture.hpp"
#include "subprocess.hpp"
#include "tests/test_paths.hpp"

using namespace imucal;
using namespace imucal::daemontest;

namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::uint64_t chaos_seed(std::uint64_t fallback) {
  const char* s = std::getenv("IMUCAL_CHAOS_SEED");
  return s != nullptr && *s != '\0' ? std::strtoull(s, nullptr, 10) : fallback;
}

double env_number(const char* name, double fallback) {
  const char* s = std::getenv(name);
  return s != nullptr && *s != '\0' ? std::atof(s) : fallback;
}

// A fault of the campaign's sim_faults, with the words of the suspension it must cause.
struct PlannedFault {
  json spec;
  std::vector<std::string> reasons;  // any of them in the suspension's reason
  std::string label;
};

// `n` instants in [lo, hi], sorted, at least `gap` apart, drawn from `rng`.
std::vector<double> instants(std::mt19937_64& rng, std::size_t n, double lo, double hi, double gap) {
  std::uniform_real_distribution<double> u(lo, hi);
  for (int attempt = 0; attempt < 100000; ++attempt) {
    std::vector<double> t(n);
    for (auto& x : t) x = std::round(u(rng) * 10.0) / 10.0;
    std::sort(t.begin(), t.end());
    bool ok = true;
    for (std::size_t i = 1; i < n; ++i) ok = ok && t[i] - t[i - 1] >= gap;
    if (ok) return t;
  }
  ADD_FAILURE() << "no " << n << " instants " << gap << " s apart in [" << lo << ", " << hi << "]";
  return {};
}

// The overnight soaks' schedule: each fault at a random instant of [300 s, end - 300 s] (its
// `at_s` set in `faults`), in random order, and three kills where the run's stored progress passes
// them (stored once a second of wall time: `time_scale` program seconds), so not in the last
// stretch, which may pass between two updates. Empty kills (and a test failure) when none fit.
struct Schedule {
  json sim_faults;
  std::vector<double> kill_at;
};
constexpr std::size_t kKills = 3;
Schedule schedule(std::mt19937_64& rng, std::vector<PlannedFault>& faults, double duration_s, double time_scale) {
  std::vector<double> at = instants(rng, faults.size(), 300.0, duration_s - 300.0, duration_s / 40.0);
  std::shuffle(at.begin(), at.end(), rng);
  std::vector<double> kill_at = instants(rng, kKills, 600.0, duration_s - 5.0 * time_scale, duration_s / 10.0);
  if (at.size() != faults.size() || kill_at.size() != kKills) return {json::array(), {}};
  Schedule out{json::array(), std::move(kill_at)};
  for (std::size_t i = 0; i < faults.size(); ++i) {
    faults[i].spec["at_s"] = at[i];
    out.sim_faults.push_back(faults[i].spec);
  }
  return out;
}

std::vector<json> events_of(const json& c, const std::string& kind) {
  std::vector<json> out;
  for (const auto& e : c.at("events"))
    if (e.at("kind") == kind) out.push_back(e);
  return out;
}

// Each fault matched, in the order of its instant, to the first suspension not yet taken at or
// after it whose reason names it. Returns the suspensions matched (index into `suspensions`, or
// -1 when none: the fault left no mark).
std::vector<int> match_faults(const std::vector<PlannedFault>& faults, const std::vector<json>& suspensions) {
  std::vector<int> matched(faults.size(), -1);
  std::vector<bool> taken(suspensions.size(), false);
  std::vector<std::size_t> order(faults.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return faults[a].spec.at("at_s").get<double>() < faults[b].spec.at("at_s").get<double>();
  });
  for (const std::size_t f : order) {
    const double at_s = faults[f].spec.at("at_s").get<double>();
    for (std::size_t s = 0; s < suspensions.size(); ++s) {
      if (taken[s]) continue;
      const json& t = suspensions[s].at("program_time_s");
      if (!t.is_number() || t.get<double>() < at_s - 1.0) continue;
      const std::string reason = suspensions[s].at("reason").get<std::string>();
      if (std::none_of(faults[f].reasons.begin(), faults[f].reasons.end(),
                       [&](const std::string& r) { return reason.find(r) != std::string::npos; }))
        continue;
      taken[s] = true;
      matched[f] = static_cast<int>(s);
      break;
    }
  }
  return matched;
}

bool same_temp(const TempSample& a, const TempSample& b) {
  return a.t_ns == b.t_ns && a.gyro_C == b.gyro_C && a.accel_C == b.accel_C && a.chamber_C == b.chamber_C &&
         a.chamber_setpoint_C == b.chamber_setpoint_C;
}

// The daemon as a subprocess that the test may kill; SIGTERM at the end of the test.
struct Imucald {
  std::string data_dir, log;
  const char* devices;
  DaemonProcess p;
  std::vector<std::string> more_args;  // e.g. --config FILE
  void start() {
    p = spawn_imucald(imucaltest::program("imucald"), data_dir, log, kOperatorToken, devices, more_args);
    ASSERT_GT(p.port, 0) << "imucald did not start; see " << log;
  }
  Client client() const { return Client{p.port, kOperatorToken}; }
  void kill9() {
    if (p.pid <= 0) return;  // already ended (wait_watching said how)
    ::kill(p.pid, SIGKILL);
    EXPECT_EQ(wait_exit(p.pid, 30), 128 + SIGKILL);
    p = {};
  }
  ~Imucald() {
    if (p.pid > 0) {
      ::kill(p.pid, SIGTERM);
      wait_exit(p.pid, 60);
    }
  }
};

std::int64_t post_and_start(const Client& op, const json& campaign) {
  const auto posted = op.post("/api/campaigns", campaign.dump());
  EXPECT_EQ(posted.status, 201) << posted.body.substr(0, 2000);
  const auto id = posted.json_body().value("id", std::int64_t{0});
  EXPECT_EQ(op.post("/api/campaigns/" + std::to_string(id) + "/start").status, 200);
  return id;
}

// thermal-short with its profile, then the programs of the built-in campaign `full`; the thermal
// truth makes the temperatures and the coefficients follow the profile.
json overnight_campaign(double rate_hz, std::uint64_t seed) {
  return {{"name", "chaos overnight"},
          {"program", {"thermal-short", "direct", "lever-arm", "navigation", "evaluate"}},
          {"chamber", {{"profile", "thermal-short"}}},
          {"truth", json::parse(std::ifstream(imucaltest::source_dir() + "/examples/truth-thermal.json"))},
          {"rate_hz", rate_hz},
          {"seed", seed % 1000 + 1}};
}

// Every stage's estimates of `disturbed` against `undisturbed`'s, in the latter's sigma; each
// must be within `max_sigma` of it (and a number), and there must be a model of all stages (a
// stage without estimates fails unless `max_sigma` is infinite: then it is only counted).
struct ModelDifference {
  double worst_sigma = 0.0;
  std::string worst_name;
  int compared = 0;
  std::vector<std::string> without_model;  // stages the disturbed run has no estimates of
};
ModelDifference compare_models(const json& disturbed, const json& undisturbed, double max_sigma) {
  ModelDifference d;
  for (const auto& [stage, result] : undisturbed.at("results").items()) {
    if (!result.is_object() || !result.contains("estimates")) continue;
    const json& results = disturbed.at("results");
    if (!results.contains(stage) || !results.at(stage).contains("estimates")) {
      d.without_model.push_back(stage);
      if (std::isfinite(max_sigma)) {
        ADD_FAILURE() << "the disturbed run has no estimates of " << stage << ": "
                      << results.value(stage, json()).dump().substr(0, 1000);
      }
      continue;
    }
    const json& mine = results.at(stage).at("estimates");
    for (const auto& [name, pair] : result.at("estimates").items()) {
      const double sigma = pair.at(1).get<double>();
      if (!(sigma > 0)) continue;
      const double diff = std::abs(mine.at(name).at(0).get<double>() - pair.at(0).get<double>()) / sigma;
      if (diff >= d.worst_sigma) {
        d.worst_sigma = diff;
        d.worst_name = stage + " " + name;
      }
      ++d.compared;
      EXPECT_LE(diff, max_sigma) << stage << " " << name << ": disturbed " << mine.at(name).dump() << ", undisturbed "
                           << pair.dump();
    }
  }
  if (std::isfinite(max_sigma)) {
    EXPECT_GE(d.compared, 36);
  }
  EXPECT_TRUE(disturbed.at("has_model").get<bool>());
  return d;
}

// A recording against the program's frame grid (dt_ns apart from dt_ns on).
struct GridCheck {
  std::size_t grid = 0, lost = 0, duplicated = 0, off_grid = 0;
};
GridCheck check_grid(const std::vector<ImuFrame>& frames, double duration_s, double rate_hz) {
  const auto dt_ns = std::llround(1e9 / rate_hz);
  GridCheck g;
  g.grid = static_cast<std::size_t>(std::llround(duration_s * rate_hz));
  g.off_grid = frames.empty() || frames.front().t_ns != dt_ns;
  for (std::size_t i = 1; i < frames.size(); ++i) {
    g.duplicated += frames[i].t_ns <= frames[i - 1].t_ns;
    g.off_grid += frames[i].t_ns - frames[i - 1].t_ns != dt_ns;
  }
  g.lost = g.grid > frames.size() ? g.grid - frames.size() : 0;
  EXPECT_EQ(frames.size(), g.grid);
  EXPECT_EQ(g.duplicated, 0u);
  EXPECT_EQ(g.off_grid, 0u);
  return g;
}

bool final_state(const json& c) {
  const auto s = c.value("state", "");
  return s == "done" || s == "failed" || s == "aborted";
}

// gdb's stacks of every thread (`args`: the process or the program and its core), lines cut at 300
// characters (a frame inside Boost's templates runs to thousands), or why there are none.
std::string gdb(const std::string& args) {
  if (::access("/usr/bin/gdb", X_OK) != 0) return "(no stacks: gdb is not installed, scripts/install-deps.sh installs it)";
  const std::string command = "/usr/bin/gdb -batch -ex 'thread apply all bt' " + args + " 2>&1";
  std::string out;
  if (FILE* p = ::popen(command.c_str(), "r")) {
    char buf[4096];
    while (std::fgets(buf, sizeof buf, p)) {
      const std::string line(buf);
      out += line.size() > 300 ? line.substr(0, 300) + "...\n" : line;
    }
    ::pclose(p);
  }
  return out;
}

// The stacks of every thread of the running process `pid`.
std::string thread_stacks(pid_t pid) { return gdb("-p " + std::to_string(pid)); }

// The stacks in the core a dead daemon left in its log's directory (spawn_imucald runs it there),
// or where none was found.
std::string core_stacks(const Imucald& d, pid_t pid) {
  const std::string dir = d.log.substr(0, d.log.rfind('/'));
  const std::string names[] = {"core." + std::to_string(pid), "core"};
  for (const std::string& name : names) {
    if (::access((dir + "/" + name).c_str(), R_OK) == 0)
      return gdb(imucaltest::program("imucald") + " " + dir + "/" + name);
  }
  return "(no core file in " + dir + "; /proc/sys/kernel/core_pattern decides where cores go)";
}

std::string log_tail(const Imucald& d) {
  std::ifstream log(d.log);
  const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  return text.substr(text.size() > 6000 ? text.size() - 6000 : 0);
}

// Waits for `done` (the run's end) as wait_for does, and watches the run and its daemon: a daemon
// that ends on its own is a failure said at once, with its exit status and, when it died of a
// signal and left a core, its stacks; a run whose program time stands still for `stall_s` of wall
// time (no fault of the soaks lasts a tenth of that) is a hang, its daemon's stacks printed. So a
// crash or a hang seen once under load says where it happened. Null after either.
json wait_watching(Imucald& d, std::int64_t id, double timeout_s, const std::function<bool(const json&)>& done = final_state,
                   double stall_s = 240.0) {
  const auto deadline = Clock::now() + std::chrono::duration<double>(timeout_s);
  double last_t_s = -1.0;
  auto last_move = Clock::now();
  json last;
  while (Clock::now() < deadline) {
    if (const auto status = exited(d.p.pid)) {
      const pid_t pid = d.p.pid;
      d.p = {};
      ADD_FAILURE() << "imucald (process " << pid << ") ended on its own with status " << *status
                    << (*status > 128 ? " (signal " + std::to_string(*status - 128) + ")" : std::string())
                    << " while campaign " << id << " ran; its stacks:\n" << core_stacks(d, pid)
                    << "\nthe log's end:\n" << log_tail(d) << "\nthe campaign as last read: " << last.dump().substr(0, 2000);
      return json();
    }
    const json now = d.client().get_json("/api/campaigns/" + std::to_string(id));
    if (now.is_object()) last = now;
    if (now.is_object() && done(now)) return now;
    const double t_s = now.is_object() ? now.value("program_time_s", -1.0) : -1.0;
    if (t_s != last_t_s) {
      last_t_s = t_s;
      last_move = Clock::now();
    } else if (since(last_move) > stall_s) {
      ADD_FAILURE() << "campaign " << id << "'s program time stood at " << t_s << " s for " << stall_s
                    << " s of wall time; its daemon's threads:\n" << thread_stacks(d.p.pid) << "\nthe log's end:\n"
                    << log_tail(d) << "\nthe campaign: " << last.dump().substr(0, 2000);
      return json();
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  ADD_FAILURE() << "timed out waiting on campaign " << id << "; last: " << last.dump().substr(0, 2000);
  return last;
}

// Kills the daemon when the run's stored program time passes each of `kill_at_s`, restarts it and
// resumes the run; returns the program time (stored) at each kill. Then waits for the run's end.
// `after_kill(run)` looks at the campaign as it stood before each kill while the daemon is down.
json run_with_kills(Imucald& d, std::int64_t id, const std::vector<double>& kill_at_s, double timeout_s,
                    std::vector<double>& killed_at_s, const std::function<void(const json&)>& after_kill = {}) {
  const auto deadline = Clock::now() + std::chrono::duration<double>(timeout_s);
  for (const double at_s : kill_at_s) {
    const json before = wait_watching(d, id, std::max(1.0, std::chrono::duration<double>(deadline - Clock::now()).count()),
                                      [&](const json& c) { return final_state(c) || c.at("program_time_s").get<double>() >= at_s; });
    if (before.is_null()) return before;  // wait_watching said why
    if (final_state(before) || !before.contains("program_time_s")) {
      ADD_FAILURE() << "the run ended before the kill at " << at_s << " s: " << before.dump().substr(0, 2000);
      return before;
    }
    d.kill9();
    killed_at_s.push_back(before.at("program_time_s").get<double>());
    if (after_kill) after_kill(before);
    d.start();
    if (d.p.port == 0) return json();
    const Client op = d.client();
    const json found = op.get_json("/api/campaigns/" + std::to_string(id));
    EXPECT_EQ(found.value("state", ""), "interrupted") << found.dump().substr(0, 1000);
    const auto resumed = op.post("/api/campaigns/" + std::to_string(id) + "/resume");
    EXPECT_EQ(resumed.status, 200) << resumed.body;
    // The next kill after this one's resumption is under way (the stored progress is still the
    // killed process's, which may be past the next instant already).
    const std::size_t kills = killed_at_s.size();
    op.wait_for(id, [&](const json& c) {
      std::size_t redos = 0;
      for (const auto& e : c.at("events")) redos += e.at("kind") == "redo";
      return final_state(c) || redos >= kills;
    }, std::max(1.0, std::chrono::duration<double>(deadline - Clock::now()).count()));
  }
  return wait_watching(d, id, std::max(1.0, std::chrono::duration<double>(deadline - Clock::now()).count()));
}

// The faults of the wire (sim-wire), drawn from `rng`: durations drawn in seconds of host time
// (what the drivers' timeouts count) and given in program seconds, `scale` of them a host second.
std::vector<PlannedFault> wire_faults(std::mt19937_64& rng, double scale) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto host_seconds = [&](double lo, double hi) { return std::round((lo + (hi - lo) * u(rng)) * scale * 10.0) / 10.0; };
  return {
      {{{"kind", "imu_corrupt"}, {"frames", 1 + static_cast<int>(u(rng) * 5)}}, {"frame(s) missing", "corrupt IMU"},
       "IMU samples corrupted (CRC)"},
      {{{"kind", "imu_drop"}, {"frames", 1 + static_cast<int>(u(rng) * 20)}}, {"frame(s) missing"},
       "IMU samples dropped"},
      {{{"kind", "imu_dropout"}, {"duration_s", host_seconds(2, 4)}}, {"frame(s) missing", "IMU frames missing", "IMU:"},
       "IMU silent for seconds"},
      {{{"kind", "disconnect"}, {"device", "chamber"}, {"duration_s", host_seconds(1, 2)}}, {"chamber disconnected"},
       "Modbus timeouts"},
      {{{"kind", "disconnect"}, {"device", "chamber"}, {"duration_s", host_seconds(6, 10)}}, {"chamber disconnected"},
       "chamber stops answering"},
      {{{"kind", "drop_connection"}, {"device", "table"}}, {"table"}, "table connection dropped"},
  };
}

// A soak's two runs on one daemon: the disturbed campaign with its kills, then the reference
// undisturbed (none when reference_spec is null). The caller checks that both ended `done`.
struct SoakRuns {
  json disturbed, undisturbed;
  std::vector<double> killed_at_s;
  double disturbed_wall_s = 0.0, undisturbed_wall_s = 0.0;
};
SoakRuns run_soak(Imucald& d, const json& disturbed_spec, const json& reference_spec, const std::vector<double>& kill_at_s,
                  const std::function<void(const json&)>& after_kill = {}) {
  SoakRuns r;
  const auto t0 = Clock::now();
  const auto id = post_and_start(d.client(), disturbed_spec);
  r.disturbed = run_with_kills(d, id, kill_at_s, 1800.0, r.killed_at_s, after_kill);
  r.disturbed_wall_s = since(t0);
  if (!r.disturbed.is_object()) r.disturbed = json::object();  // a crash or a hang, said already
  if (r.disturbed.value("state", "") != "done" || d.p.port == 0 || reference_spec.is_null()) return r;
  const auto t1 = Clock::now();
  const auto id2 = post_and_start(d.client(), reference_spec);
  r.undisturbed = wait_watching(d, id2, 1800.0);
  if (!r.undisturbed.is_object()) r.undisturbed = json::object();
  r.undisturbed_wall_s = since(t1);
  return r;
}

// One line per fault: where it was injected and the suspension that marked it.
void print_faults(const std::vector<PlannedFault>& faults, const std::vector<int>& matched,
                  const std::vector<json>& suspensions) {
  for (std::size_t i = 0; i < faults.size(); ++i) {
    std::string mark = "no suspension (absorbed by the driver)";
    if (matched[i] >= 0) {
      const json& s = suspensions[static_cast<std::size_t>(matched[i])];
      mark = "suspended at " + number_text(s.at("program_time_s").get<double>()) +
             " s: " + s.at("reason").get<std::string>().substr(0, 90);
    }
    std::printf("  %-28s at %8.1f s -> %s\n", faults[i].label.c_str(), faults[i].spec.at("at_s").get<double>(),
                mark.c_str());
  }
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// Part A

TEST(Chaos, AnOvernightCampaignSurvivesEveryFaultThreeKillsAndAFullDisk) {
  const std::uint64_t seed = chaos_seed(33);
  SCOPED_TRACE("IMUCAL_CHAOS_SEED=" + std::to_string(seed));
  const double rate_hz = env_number("IMUCAL_CHAOS_RATE_HZ", 100.0);
  std::mt19937_64 rng(seed);

  json campaign = overnight_campaign(rate_hz, seed);
  campaign["time_scale"] = 0;
  campaign["suspenders"] = {{"settle_s", 5}, {"frame_timeout_s", 1.0}, {"chamber_persist_s", 2.0}};
  const auto check = daemon::check_campaign(campaign, daemon::DaemonConfig{});
  ASSERT_TRUE(check.spec.has_value()) << (check.problems.empty() ? "" : check.problems.front());
  const double duration_s = check.duration_s;
  const double tolerance_C = check.spec->chamber.tolerance_C;

  // Every fault kind of the simulated bench once, and three kills, at seeded instants in random
  // order, far enough apart that each is its own suspension.
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto between = [&](double lo, double hi) { return std::round((lo + (hi - lo) * u(rng)) * 10.0) / 10.0; };
  std::vector<PlannedFault> faults = {
      {{{"kind", "imu_corrupt"}, {"frames", 1 + static_cast<int>(u(rng) * 20)}}, {"corrupt IMU frame"},
       "IMU bytes corrupted"},
      {{{"kind", "imu_drop"}, {"frames", 1 + static_cast<int>(u(rng) * 50)}}, {"frame(s) missing"},
       "IMU bytes dropped"},
      {{{"kind", "imu_dropout"}, {"duration_s", between(2, 8)}}, {"frame(s) missing", "IMU frames missing"},
       "IMU silent for seconds"},
      {{{"kind", "disconnect"}, {"device", "imu"}, {"duration_s", between(2, 10)}}, {"IMU does not answer"},
       "IMU disconnected"},
      {{{"kind", "disconnect"}, {"device", "chamber"}, {"duration_s", between(5, 30)}}, {"chamber disconnected"},
       "chamber stops answering"},
      {{{"kind", "chamber_offset"}, {"duration_s", between(10, 40)}, {"offset_C", tolerance_C + 10.0}},
       {"chamber out of band"}, "chamber reading off"},
      {{{"kind", "disconnect"}, {"device", "table"}, {"duration_s", between(2, 10)}},
       {"table disconnected", "table does not answer"}, "table connection lost"},
      {{{"kind", "table_fault"}, {"duration_s", between(1, 5)}}, {"table fault", "table drive fault"},
       "table drive fault"},
      {{{"kind", "disk_full"}, {"duration_s", between(5, 20)}}, {"disk full"}, "disk full"},
  };
  constexpr double kTimeScale = 500.0;
  const Schedule sched = schedule(rng, faults, duration_s, kTimeScale);
  const json& sim_faults = sched.sim_faults;
  const std::vector<double>& kill_at = sched.kill_at;
  ASSERT_FALSE(kill_at.empty());
  std::printf("chaos A: seed %llu, %.0f s of program at %g Hz; faults %s; kill -9 at %.0f, %.0f, %.0f s\n",
              static_cast<unsigned long long>(seed), duration_s, rate_hz, sim_faults.dump().c_str(), kill_at[0],
              kill_at[1], kill_at[2]);

  const std::string dir = scratch_dir("chaos");
  Imucald d{dir + "/data", dir + "/imucald.stderr", "sim", {}, {}};
  d.start();
  ASSERT_GT(d.p.port, 0);

  // Paced, so that the kills land near their instants; the frames do not depend on the pace.
  json disturbed_spec = campaign;
  disturbed_spec["name"] = "chaos overnight, faults and kills";
  disturbed_spec["time_scale"] = kTimeScale;
  disturbed_spec["sim_faults"] = sim_faults;
  const SoakRuns runs = run_soak(d, disturbed_spec, campaign, kill_at);
  const json& disturbed = runs.disturbed;
  const json& undisturbed = runs.undisturbed;
  const std::vector<double>& killed_at = runs.killed_at_s;
  ASSERT_EQ(disturbed.value("state", ""), "done") << disturbed.dump().substr(0, 4000) << "\nsee " << d.log;
  ASSERT_EQ(killed_at.size(), kKills);
  ASSERT_EQ(undisturbed.value("state", ""), "done") << undisturbed.dump().substr(0, 3000);

  // Marked: each fault a suspension of the run naming it (an event of the run in the daemon's
  // database and in the run file's imucald_run record), each kill a redo from the last commit.
  const std::vector<json> suspensions = events_of(disturbed, "suspended");
  const std::vector<int> matched = match_faults(faults, suspensions);
  std::size_t survived = 0;
  for (std::size_t i = 0; i < faults.size(); ++i) {
    EXPECT_GE(matched[i], 0) << faults[i].label << " (" << faults[i].spec.dump() << ") left no suspension; "
                             << json(suspensions).dump().substr(0, 4000);
    survived += matched[i] >= 0;
  }
  // A kill may land while the run is suspended: that suspension ends with the process.
  EXPECT_GE(events_of(disturbed, "resumed").size() + kKills, suspensions.size());
  EXPECT_EQ(events_of(disturbed, "redo").size(), kKills);
  const std::string run_path = dir + "/data/" + disturbed.at("run_db").get<std::string>();
  const auto run_db = storage::RunDb::open(run_path, storage::OpenMode::Read);
  const json record = json::parse(run_db.extra("imucald_run").value_or("{}"));
  std::size_t recorded_suspensions = 0;
  for (const auto& e : record.value("events", json::array())) recorded_suspensions += e.at("kind") == "suspended";
  EXPECT_EQ(recorded_suspensions, suspensions.size()) << "the run file's record of the faulted intervals";

  // The recording: every frame of the undisturbed run once, bit for bit, nothing else.
  const auto got = run_db.read_frames();
  const auto want = run_frames(dir + "/data/" + undisturbed.at("run_db").get<std::string>());
  std::size_t duplicated = 0, lost = 0, differing = 0;
  for (std::size_t i = 1; i < got.size(); ++i) duplicated += got[i].t_ns <= got[i - 1].t_ns;
  {
    std::size_t i = 0, j = 0;
    while (j < want.size()) {
      while (i < got.size() && got[i].t_ns < want[j].t_ns) ++i;
      if (i < got.size() && got[i].t_ns == want[j].t_ns) {
        differing += !same_frame(got[i], want[j]);
      } else {
        ++lost;
      }
      ++j;
    }
  }
  EXPECT_EQ(duplicated, 0u);
  EXPECT_EQ(lost, 0u);
  EXPECT_EQ(differing, 0u);
  EXPECT_EQ(got.size(), want.size());
  EXPECT_EQ(static_cast<double>(want.size()), std::round(duration_s * rate_hz));
  EXPECT_TRUE(run_db.dropped_spans().empty());

  // The temperature records: the same instants; values the same except the chamber's reading in
  // a chamber fault's interval (what it read before the run suspended on it: marked).
  const auto temps = run_db.temps();
  const auto want_temps = storage::RunDb::open(dir + "/data/" + undisturbed.at("run_db").get<std::string>(),
                                               storage::OpenMode::Read)
                              .temps();
  EXPECT_EQ(temps.size(), want_temps.size());
  std::size_t temps_differing = 0, temps_unmarked = 0;
  for (std::size_t i = 0; i < std::min(temps.size(), want_temps.size()); ++i) {
    if (same_temp(temps[i], want_temps[i])) continue;
    ++temps_differing;
    const double t_s = static_cast<double>(temps[i].t_ns) * 1e-9;
    bool marked = false;
    for (const auto& s : suspensions) {
      const double ts = s.at("program_time_s").get<double>();
      if (s.at("reason").get<std::string>().find("chamber") != std::string::npos && t_s >= ts - 60.0 && t_s <= ts + 1.0)
        marked = true;
    }
    if (!marked && temps_unmarked++ < 3)
      ADD_FAILURE() << "temperature record at " << t_s << " s differs outside a marked fault: chamber "
                    << temps[i].chamber_C << " vs " << want_temps[i].chamber_C;
  }
  EXPECT_EQ(temps_unmarked, 0u);

  // The models: every stage's estimates within 0.1 of the undisturbed run's sigma.
  const ModelDifference model = compare_models(disturbed, undisturbed, 0.1);

  std::printf(
      "chaos soak A (sim, %.0f s of program at %g Hz, %zu frames): faults injected %zu + kill -9 %zu (at %.0f, %.0f, "
      "%.0f s), survived %zu + %zu; suspensions %zu; frames lost %zu, duplicated %zu, differing %zu; temperature "
      "records differing %zu (all in marked chamber faults); delivery gaps counted %lld frames, bad frames %lld; "
      "worst model difference %.3g sigma (%s) over %d coefficients; wall %.0f s disturbed (500x), %.0f s undisturbed "
      "(as fast as possible)\n",
      duration_s, rate_hz, want.size(), faults.size(), kKills, killed_at[0], killed_at[1], killed_at[2], survived,
      killed_at.size(), suspensions.size(), lost, duplicated, differing, temps_differing,
      static_cast<long long>(disturbed.at("lost_frames").get<std::int64_t>()),
      static_cast<long long>(disturbed.at("bad_frames").get<std::int64_t>()), model.worst_sigma, model.worst_name.c_str(),
      model.compared, runs.disturbed_wall_s, runs.undisturbed_wall_s);
  print_faults(faults, matched, suspensions);
}

// ------------------------------------------------------------------------------------------------
// Part B

TEST(Chaos, TheWireLevelDevicesSurviveTheirFaultsAndAKill) {
  const std::uint64_t seed = chaos_seed(33);
  SCOPED_TRACE("IMUCAL_CHAOS_SEED=" + std::to_string(seed));
  std::mt19937_64 rng(seed);
  const json program = json::parse(R"({"name": "chaos-wire", "segments": [
    {"type": "hold", "name": "start", "duration_s": 4},
    {"type": "move", "name": "tilt", "to_deg": [0, 90, 0], "duration_s": 3},
    {"type": "hold", "name": "level", "duration_s": 5},
    {"type": "rate", "name": "spin", "axis": "outer", "rate_dps": 20, "duration_s": 6, "accel_dps2": 40},
    {"type": "hold", "name": "rest", "duration_s": 5},
    {"type": "move", "name": "back", "to_deg": [0, 0, 0], "duration_s": 3},
    {"type": "hold", "name": "flat", "duration_s": 5},
    {"type": "rate", "name": "turn", "axis": "inner", "rate_dps": 15, "duration_s": 5, "accel_dps2": 30},
    {"type": "hold", "name": "end", "duration_s": 4}]})");
  json campaign = {{"name", "chaos wire"},       {"program", program},  {"rate_hz", 100},
                   {"seed", seed % 1000 + 1},    {"truth", noisy_truth()}, {"estimators", json::array()},
                   {"suspenders", {{"settle_s", 2}, {"frame_timeout_s", 1.0}, {"chamber_persist_s", 2.0}}}};
  daemon::DaemonConfig sim_wire;
  sim_wire.devices = "sim-wire";
  const auto check = daemon::check_campaign(campaign, sim_wire);
  ASSERT_TRUE(check.spec.has_value()) << (check.problems.empty() ? "" : check.problems.front());
  const double duration_s = check.duration_s;

  std::vector<PlannedFault> faults = wire_faults(rng, 1.0);
  std::vector<double> at = instants(rng, faults.size() + 1, 2.0, duration_s - 2.0, 4.0);
  ASSERT_EQ(at.size(), faults.size() + 1);
  std::shuffle(at.begin(), at.end(), rng);
  const double kill_at = at.back();
  json sim_faults = json::array();
  for (std::size_t i = 0; i < faults.size(); ++i) {
    faults[i].spec["at_s"] = at[i];
    sim_faults.push_back(faults[i].spec);
  }
  campaign["sim_faults"] = sim_faults;
  std::printf("chaos B: seed %llu, %.0f s of program at 100 Hz; faults %s; kill -9 at %.1f s\n",
              static_cast<unsigned long long>(seed), duration_s, sim_faults.dump().c_str(), kill_at);

  const std::string dir = scratch_dir("chaos-wire");
  Imucald d{dir + "/data", dir + "/imucald.stderr", "sim-wire", {}, {}};
  d.start();
  ASSERT_GT(d.p.port, 0);
  const auto t0 = Clock::now();
  const auto id = post_and_start(d.client(), campaign);
  std::vector<double> killed_at;
  // What was committed at the kill, read between the kill and the restart.
  std::vector<ImuFrame> committed;
  std::string run_path;
  {
    const json before = d.client().wait_for(id, [&](const json& c) {
      return final_state(c) || c.at("program_time_s").get<double>() >= kill_at;
    }, 600.0);
    // Running, or suspended by a fault or by the machine's load (a stall of the real-time link).
    ASSERT_TRUE(before.value("state", "") == "running" || before.value("state", "") == "suspended")
        << before.dump().substr(0, 3000);
    d.kill9();
    killed_at.push_back(before.at("program_time_s").get<double>());
    run_path = dir + "/data/" + before.at("run_db").get<std::string>();
    committed = run_frames(run_path);
    d.start();
    ASSERT_GT(d.p.port, 0);
    EXPECT_EQ(d.client().get_json("/api/campaigns/" + std::to_string(id)).value("state", ""), "interrupted");
    ASSERT_EQ(d.client().post("/api/campaigns/" + std::to_string(id) + "/resume").status, 200);
  }
  const json c = d.client().wait_for(id, final_state, 900.0);
  const double wall_s = since(t0);
  ASSERT_EQ(c.value("state", ""), "done") << c.dump().substr(0, 4000) << "\nsee " << d.log;
  EXPECT_TRUE(has_event(c, "redo", "resuming after an interruption"));

  // The grid: every instant of the program once, none lost, none doubled; what was committed
  // before the kill unchanged.
  const auto frames = run_frames(run_path);
  const GridCheck g = check_grid(frames, duration_s, 100.0);
  std::size_t changed = 0;
  for (std::size_t i = 0; i < std::min(committed.size(), frames.size()); ++i) changed += !same_frame(frames[i], committed[i]);
  EXPECT_EQ(changed, 0u) << "frames committed before the kill changed";
  EXPECT_GT(committed.size(), 0u);
  EXPECT_EQ(c.at("frames").get<std::int64_t>(), static_cast<std::int64_t>(frames.size()));

  // Marked: each fault a suspension naming it. The table's dropped connection may be absorbed by
  // the driver's reconnect without a suspension; the others cannot be.
  const std::vector<json> suspensions = events_of(c, "suspended");
  const std::vector<int> matched = match_faults(faults, suspensions);
  std::size_t marked = 0;
  for (std::size_t i = 0; i < faults.size(); ++i) {
    marked += matched[i] >= 0;
    if (faults[i].spec.at("kind") == "drop_connection") continue;
    EXPECT_GE(matched[i], 0) << faults[i].label << " (" << faults[i].spec.dump() << ") left no suspension; "
                             << json(suspensions).dump().substr(0, 4000);
  }
  std::printf(
      "chaos soak B (sim-wire, real time, %.0f s of program at 100 Hz, %zu grid frames): faults injected %zu + kill "
      "-9 1 (at %.1f s), survived %zu + 1 (%zu marked by a suspension); suspensions %zu; frames lost %zu, "
      "duplicated %zu, off the grid %zu, committed before the kill and changed %zu of %zu; delivery gaps counted "
      "%lld frames, bad frames %lld; wall %.0f s\n",
      duration_s, g.grid, faults.size(), killed_at[0], faults.size(), marked, suspensions.size(), g.lost, g.duplicated,
      g.off_grid, changed, committed.size(), static_cast<long long>(c.at("lost_frames").get<std::int64_t>()),
      static_cast<long long>(c.at("bad_frames").get<std::int64_t>()), wall_s);
  print_faults(faults, matched, suspensions);
}

// ------------------------------------------------------------------------------------------------
// Part C, the overnight campaign through the wire: Part A's campaign on `--devices sim-wire`,
// accelerated (imucald's sim.wire_time_scale, IMUCAL_CHAOS_WIRE_SCALE, 200x unless given), with
// the wire's faults, kill -9 three times and the disk full once.
//
// What cannot be checked, and why: through real sockets a run is not reproducible frame for
// frame. The instants the controller receives its demands, the table reads the bench interpolates
// between and the samples the host stamps all depend on the scheduler; at 200x a millisecond of
// host time is 0.2 s of program. So the recording is checked against the program's grid (every
// instant once: none lost, none doubled) and the frames committed before each kill against the
// recording at the end (unchanged). The model could only be compared with an undisturbed run's,
// with the difference reported, not held to 0.1 sigma; that run doubles the soak's time, so it is
// made only when asked (IMUCAL_CHAOS_WIRE_REFERENCE=1): two undisturbed runs at 200x already differ by
// thousands of sigma in the lever arms (the lever-arm program's 2 s oscillations last 10 ms of
// host time, a few table reads apart, so the frames' interpolated angles differ run to run) and by
// tens in stage 1's gyro scale; at 50x direct-short's two runs differ by up to 2 sigma. Stage 1
// is sometimes far off in either run (accelerometer residuals 0.03 m/s^2 against 4e-5): the
// estimators take a static from the program's segment times, and a demand that reaches the table
// 5 ms of host time late moves it a second of program into the static. Stage 3 then refuses to
// converge ("stage-1 errors too large"), which is counted and printed, not failed. The model's
// 0.1 sigma is Part A's check, on the bench that is reproducible.

namespace {

// A frame's identity, cheap to keep for millions of frames (FNV-1a over its fields' bytes).
std::uint64_t frame_digest(const ImuFrame& f) {
  std::uint64_t h = 1469598103934665603ull;
  auto mix = [&](const void* p, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) h = (h ^ static_cast<const unsigned char*>(p)[i]) * 1099511628211ull;
  };
  mix(&f.t_ns, sizeof f.t_ns);
  mix(f.dtheta_rad.data(), 3 * sizeof(double));
  mix(f.dv_mps.data(), 3 * sizeof(double));
  mix(f.table_deg.data(), 3 * sizeof(double));
  return h;
}

std::vector<std::uint64_t> digests(const std::vector<ImuFrame>& frames) {
  std::vector<std::uint64_t> d(frames.size());
  std::transform(frames.begin(), frames.end(), d.begin(), frame_digest);
  return d;
}

}  // namespace

namespace {

// Part C's reference, when asked for: the undisturbed run's grid, how many frames the disturbed
// run shares with it bit for bit (none expected through sockets), and the models' difference in
// sigma, measured and reported only (see the comment above Part C).
void report_reference(const std::string& dir, const json& disturbed, const json& undisturbed,
                      const std::vector<ImuFrame>& frames, double duration_s, double rate_hz, double wall_s) {
  const auto reference = run_frames(dir + "/data/" + undisturbed.at("run_db").get<std::string>());
  const GridCheck grid = check_grid(reference, duration_s, rate_hz);
  std::size_t bit_identical = 0;
  for (std::size_t i = 0; i < std::min(frames.size(), reference.size()); ++i)
    bit_identical += same_frame(frames[i], reference[i]);
  const ModelDifference model = compare_models(disturbed, undisturbed, std::numeric_limits<double>::infinity());
  std::printf("  reference (undisturbed, wall %.0f s): lost %zu, duplicated %zu, off the grid %zu; bit-identical to it "
              "%zu; worst model difference %.3g sigma (%s) over %d coefficients, stages without a model %zu\n",
              wall_s, grid.lost, grid.duplicated, grid.off_grid, bit_identical, model.worst_sigma,
              model.worst_name.c_str(), model.compared, model.without_model.size());
  for (const std::string& stage : model.without_model)
    std::printf("  no estimates of %s: %s\n", stage.c_str(),
                disturbed.at("results").value(stage, json()).value("message", "").substr(0, 200).c_str());
}

}  // namespace

TEST(Chaos, TheOvernightCampaignThroughTheWireSurvivesEveryFaultThreeKillsAndAFullDisk) {
  const std::uint64_t seed = chaos_seed(33);
  SCOPED_TRACE("IMUCAL_CHAOS_SEED=" + std::to_string(seed));
  const double scale = env_number("IMUCAL_CHAOS_WIRE_SCALE", 200.0);
  // The undisturbed reference run only measures (the comment above): it doubles the soak's time,
  // so it runs when asked (IMUCAL_CHAOS_WIRE_REFERENCE=1), not in every CI run.
  const bool with_reference = env_number("IMUCAL_CHAOS_WIRE_REFERENCE", 0.0) != 0.0;
  constexpr double kRateHz = 100.0;
  std::mt19937_64 rng(seed);

  // Device time is program time: a suspender's persistence, a fault's duration. The wire's
  // timeouts are host time, so what must outlast them is drawn in host seconds times the scale:
  // a frame is late only after half a second of host time, a fault lasts seconds of host time.
  json campaign = overnight_campaign(kRateHz, seed);
  campaign["name"] = "chaos overnight through the wire";
  campaign["suspenders"] = {{"settle_s", 5}, {"frame_timeout_s", 0.5 * scale}, {"chamber_persist_s", 0.25 * scale}};
  daemon::DaemonConfig sim_wire;
  sim_wire.devices = "sim-wire";
  const auto check = daemon::check_campaign(campaign, sim_wire);
  ASSERT_TRUE(check.spec.has_value()) << (check.problems.empty() ? "" : check.problems.front());
  const double duration_s = check.duration_s;

  // Part B's faults, then those a short real-time run does not have room for.
  std::vector<PlannedFault> faults = wire_faults(rng, scale);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto host_seconds = [&](double lo, double hi) { return std::round((lo + (hi - lo) * u(rng)) * scale); };
  faults.push_back({{{"kind", "imu_bytes_drop"}, {"frames", 1 + static_cast<int>(u(rng) * 20)}},
                    {"frame(s) missing", "corrupt IMU"}, "IMU bytes dropped"});
  faults.push_back({{{"kind", "chamber_corrupt"}, {"replies", 1 + static_cast<int>(u(rng) * 5)}}, {"chamber"},
                    "Modbus replies corrupt"});
  faults.push_back({{{"kind", "disconnect"}, {"device", "table"}, {"duration_s", host_seconds(1, 3)}}, {"table"},
                    "table stops answering"});
  faults.push_back({{{"kind", "disk_full"}, {"duration_s", host_seconds(2, 5)}}, {"disk full"}, "disk full"});
  // A driver's retry or reconnect may absorb these before anything shows: counted, not required.
  auto may_be_absorbed = [](const PlannedFault& f) {
    return f.spec.at("kind") == "drop_connection" || f.spec.at("kind") == "chamber_corrupt";
  };
  const Schedule sched = schedule(rng, faults, duration_s, scale);
  const json& sim_faults = sched.sim_faults;
  const std::vector<double>& kill_at = sched.kill_at;
  ASSERT_FALSE(kill_at.empty());
  std::printf("chaos C: seed %llu, %.0f s of program at %g Hz through the wire at %gx; faults %s; kill -9 at %.0f, "
              "%.0f, %.0f s\n",
              static_cast<unsigned long long>(seed), duration_s, kRateHz, scale, sim_faults.dump().c_str(), kill_at[0],
              kill_at[1], kill_at[2]);

  const std::string dir = scratch_dir("chaos-wire-overnight");
  std::ofstream(dir + "/imucald.json") << json{{"sim", {{"wire_time_scale", scale}}}}.dump();
  Imucald d{dir + "/data", dir + "/imucald.stderr", "sim-wire", {}, {"--config", dir + "/imucald.json"}};
  d.start();
  ASSERT_GT(d.p.port, 0);

  json disturbed_spec = campaign;
  disturbed_spec["name"] = "chaos overnight through the wire, faults and kills";
  disturbed_spec["sim_faults"] = sim_faults;
  // What was committed at each kill, read while the daemon is down: still there, unchanged, at
  // the end (each kill's frames checked against the previous kill's, the last kill's against the end).
  std::vector<std::uint64_t> committed;
  std::size_t committed_changed = 0;
  std::string run_path;
  auto compare_committed = [&](const std::vector<std::uint64_t>& now) {
    for (std::size_t i = 0; i < committed.size(); ++i) committed_changed += i >= now.size() || now[i] != committed[i];
  };
  const SoakRuns runs = run_soak(d, disturbed_spec, with_reference ? campaign : json(), kill_at, [&](const json& before) {
    run_path = dir + "/data/" + before.at("run_db").get<std::string>();
    const auto now = digests(run_frames(run_path));
    compare_committed(now);
    committed = now;
  });
  const json& disturbed = runs.disturbed;
  const json& undisturbed = runs.undisturbed;
  const std::vector<double>& killed_at = runs.killed_at_s;
  ASSERT_EQ(disturbed.value("state", ""), "done") << disturbed.dump().substr(0, 4000) << "\nsee " << d.log;
  ASSERT_EQ(killed_at.size(), kKills);
  if (with_reference) {
    ASSERT_EQ(undisturbed.value("state", ""), "done") << undisturbed.dump().substr(0, 3000);
  }
  EXPECT_GT(committed.size(), 0u);

  // Marked: each fault a suspension naming it, each kill a redo from the last commit.
  const std::vector<json> suspensions = events_of(disturbed, "suspended");
  const std::vector<int> matched = match_faults(faults, suspensions);
  std::size_t marked = 0;
  for (std::size_t i = 0; i < faults.size(); ++i) {
    marked += matched[i] >= 0;
    if (may_be_absorbed(faults[i])) continue;
    EXPECT_GE(matched[i], 0) << faults[i].label << " (" << faults[i].spec.dump() << ") left no suspension; "
                             << json(suspensions).dump().substr(0, 4000);
  }
  EXPECT_EQ(events_of(disturbed, "redo").size(), kKills);

  // The recording: every instant of the program once; what was committed before the kills unchanged.
  const auto frames = run_frames(run_path);
  const GridCheck g = check_grid(frames, duration_s, kRateHz);
  compare_committed(digests(frames));
  EXPECT_EQ(committed_changed, 0u) << "frames committed before a kill changed or went missing";

  std::printf(
      "chaos soak C (sim-wire at %gx, %.0f s of program at %g Hz, %zu grid frames): faults injected %zu + kill -9 %zu "
      "(at %.0f, %.0f, %.0f s), survived %zu + %zu (%zu marked by a suspension); suspensions %zu; frames lost %zu, "
      "duplicated %zu, off the grid %zu; committed before the kills and changed %zu of %zu; delivery gaps counted "
      "%lld frames, bad frames %lld; wall %.0f s\n",
      scale, duration_s, kRateHz, g.grid, faults.size(), kKills, killed_at[0], killed_at[1], killed_at[2],
      faults.size(), killed_at.size(), marked, suspensions.size(), g.lost, g.duplicated, g.off_grid, committed_changed,
      committed.size(), static_cast<long long>(disturbed.at("lost_frames").get<std::int64_t>()),
      static_cast<long long>(disturbed.at("bad_frames").get<std::int64_t>()), runs.disturbed_wall_s);
  if (with_reference) {
    report_reference(dir, disturbed, undisturbed, frames, duration_s, kRateHz, runs.undisturbed_wall_s);
  } else {
    std::printf("  no reference run (IMUCAL_CHAOS_WIRE_REFERENCE=1 runs one and reports the models' difference)\n");
  }
  print_faults(faults, matched, suspensions);
}
