#include "bench/bench_campaign.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

#include <sys/socket.h>

#include "core/hermite.hpp"
#include "drivers/tcp_table.hpp"
#include "drivers/link_imu.hpp"
#include "drivers/modbus_chamber.hpp"
#include "sim/sim_chamber.hpp"
#include "sim/sim_imu.hpp"
#include "sim/sim_table.hpp"

namespace imucal::bench {

using namespace imucal::sim;  // the simulated devices this harness drives

// The simulated devices speak the drivers' types and protocols.
using namespace imucal::drivers;

namespace {

double cpu_seconds(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

template <class T>
void require(const Result<T>& r, const char* what) {
  if (!r) throw std::runtime_error(std::string(what) + ": " + r.error().message);
}

struct TableRead {
  std::int64_t t_ns;
  std::array<double, 3> angle_deg, rate_dps;
};

struct ImuPoint {
  std::int64_t t_ns;
  Eigen::Vector3d table_deg;  // truth at the sample instant
};

// One table segment: what each axis does. Demands are repeated as the watchdog keep-alive.
struct Segment {
  std::array<TableMode, 3> mode;
  std::array<double, 3> value;  // position deg, rate deg/s, or oscillation amplitude deg
};

const std::vector<Segment>& segments() {
  static const std::vector<Segment> s = {
      {{TableMode::rate, TableMode::position, TableMode::position}, {20.0, 0.0, 0.0}},
      {{TableMode::rate, TableMode::position, TableMode::synthesis}, {-15.0, 30.0, 5.0}},
      {{TableMode::rate, TableMode::position, TableMode::synthesis}, {10.0, 30.0, 3.0}},
      {{TableMode::rate, TableMode::position, TableMode::position}, {25.0, -20.0, 0.0}},
  };
  return s;
}

}  // namespace

std::string CampaignReport::to_text() const {
  char buf[2048];
  std::snprintf(buf, sizeof buf,
                "duration                 %.1f s\n"
                "IMU samples              %llu (lost %llu in %llu gaps, CRC failures %llu, malformed %llu, stalls %llu, "
                "poll errors %llu, not sent by the device %llu)\n"
                "table reads              %llu (errors %llu)\n"
                "chamber reads            %llu (errors %llu)\n"
                "table-to-IMU alignment   rms %.1f us, 99th percentile %.1f us, max %.1f us over %llu samples\n"
                "IMU sample time vs truth rms %.1f us, max %.1f us\n"
                "clock model restarts     table %llu, IMU %llu\n"
                "driver CPU (one core)    IMU %.2f %%, table %.2f %%, chamber %.3f %%\n"
                "process CPU (one core)   %.1f %% (simulated devices and physics included)\n"
                "physics restarts         %llu (table motion changes)\n",
                duration_s, static_cast<unsigned long long>(imu_samples), static_cast<unsigned long long>(imu_lost),
                static_cast<unsigned long long>(imu_gaps), static_cast<unsigned long long>(imu_crc_failures),
                static_cast<unsigned long long>(imu_malformed), static_cast<unsigned long long>(imu_stalls),
                static_cast<unsigned long long>(imu_errors), static_cast<unsigned long long>(imu_not_sent),
                static_cast<unsigned long long>(table_reads), static_cast<unsigned long long>(table_errors),
                static_cast<unsigned long long>(chamber_reads), static_cast<unsigned long long>(chamber_errors),
                alignment_rms_us, alignment_p99_us, alignment_max_us, static_cast<unsigned long long>(alignment_points), imu_time_rms_us,
                imu_time_max_us, static_cast<unsigned long long>(table_clock_resets),
                static_cast<unsigned long long>(imu_clock_resets), imu_cpu_percent, table_cpu_percent, chamber_cpu_percent, process_cpu_percent,
                static_cast<unsigned long long>(physics_restarts));
  std::string out = buf;
  for (const auto& [what, n] : errors) out += "  error " + what + ": " + std::to_string(n) + "\n";
  return out;
}

CampaignReport run_driver_campaign(const CampaignOptions& o) {
  ServoConfig servo;
  for (auto& axis : servo.limits)
    for (auto& m : axis) m = AxisLimitSetting{-1e9, 1e9, 100.0, 100.0};
  SimWorld world(servo);

  SimTableConfig table_cfg;
  table_cfg.clock_drift_ppm = 30.0;
  table_cfg.clock_offset_us = 500'000'000'000;
  SimTable table(world, table_cfg);

  SimChamberConfig chamber_cfg;
  chamber_cfg.map = load_register_map("watlow-f4t");
  chamber_cfg.time_constant_s = 30.0;
  SimChamber chamber(chamber_cfg);

  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) != 0) throw std::runtime_error("socketpair failed");
  SimImuConfig imu_cfg;
  imu_cfg.rate_hz = o.imu_rate_hz;
  imu_cfg.framing = o.imu_rate_hz > can::kClassicMaxRate_hz ? can::Framing::fd : can::Framing::classic;
  imu_cfg.clock_drift_ppm = -20.0;
  imu_cfg.clock_offset_ns = 42'000'000'000;
  SimImu imu(world, sv[1], imu_cfg);

  TcpTableConfig tc;
  tc.port = table.port();
  tc.watchdog_s = 1.0;
  TcpTable table_driver(tc);
  ModbusChamberConfig cc;
  cc.port = chamber.port();
  cc.map = chamber_cfg.map;
  ModbusChamber chamber_driver(cc);
  LinkImuConfig ic = imu.driver_config();
  ic.stall_timeout = std::chrono::milliseconds(500);
  LinkImu imu_driver(socketcan_transport(sv[0], ic.link, imu_cfg.framing, "a socket pair"), ic);

  for (Device* d : std::initializer_list<Device*>{&table_driver, &chamber_driver, &imu_driver}) {
    require(d->connect(), "connect");
    require(d->configure(), "configure");
    require(d->activate(), "activate");
  }
  require(chamber_driver.ramp_to(30.0, 2.0), "chamber ramp");

  CampaignReport rep;
  std::mutex errors_mutex;
  auto note = [&](const char* device, const DriverError& e) {
    std::lock_guard lock(errors_mutex);
    ++rep.errors[std::string(device) + ": " + to_string(e.code)];
  };
  std::atomic<bool> stop{false};
  const double process_cpu0 = cpu_seconds(CLOCK_PROCESS_CPUTIME_ID);
  const auto wall0 = std::chrono::steady_clock::now();

  std::vector<TableRead> reads;
  reads.reserve(static_cast<std::size_t>(o.duration_s * o.table_read_hz * 1.1) + 16);
  double table_cpu = 0.0;
  std::thread table_thread([&] {
    const double cpu0 = cpu_seconds(CLOCK_THREAD_CPUTIME_ID);
    const auto start = std::chrono::steady_clock::now();
    const auto period = std::chrono::duration<double>(1.0 / o.table_read_hz);
    std::size_t seg = SIZE_MAX;
    auto next_read = start;
    auto next_feed = start;
    std::array<TableMode, 3> modes{TableMode::off, TableMode::off, TableMode::off};
    while (!stop) {
      const auto now = std::chrono::steady_clock::now();
      const double t = std::chrono::duration<double>(now - start).count();
      const std::size_t want = static_cast<std::size_t>(t / 8.0) % segments().size();
      if (want != seg || now >= next_feed) {
        const Segment& s = segments()[want];
        for (int a = 0; a < 3; ++a) {
          const auto i = static_cast<std::size_t>(a);
          if (modes[i] != s.mode[i]) {
            if (auto r = table_driver.set_mode(a, s.mode[i]); !r) {
              ++rep.table_errors;
              note("table", r.error());
            } else {
              modes[i] = s.mode[i];
            }
          }
          Result<void> r;
          if (s.mode[i] == TableMode::rate) r = table_driver.demand_rate(a, s.value[i]);
          else if (s.mode[i] == TableMode::position) r = table_driver.demand_position(a, s.value[i]);
          else r = table_driver.demand_oscillation(a, {s.value[i], 0.5, 0.0});
          if (!r) {
            ++rep.table_errors;
            note("table", r.error());
            // Recover as the daemon's sequencer does: clear latched faults, close the
            // interlock if needed, and set the mode again on the next keep-alive.
            if (r.code() == DriverErrc::watchdog_expired || r.code() == DriverErrc::axis_fault) (void)table_driver.interlock_reset();
            if (r.code() == DriverErrc::interlock_open) (void)table_driver.interlock_close();
            modes[i] = TableMode::off;  // no segment uses off: forces a mode command
          }
        }
        seg = want;
        next_feed = now + std::chrono::milliseconds(250);
      }
      if (now >= next_read) {
        auto p = table_driver.read_positions();
        if (p) {
          reads.push_back({p->t_ns, p->angle_deg, p->rate_dps});
          ++rep.table_reads;
        } else {
          ++rep.table_errors;
          note("table", p.error());
        }
        next_read += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
        if (next_read < now) next_read = now;
      }
      std::this_thread::sleep_until(std::min(next_read, next_feed));
    }
    table_cpu = cpu_seconds(CLOCK_THREAD_CPUTIME_ID) - cpu0;
  });

  double chamber_cpu = 0.0;
  std::thread chamber_thread([&] {
    const double cpu0 = cpu_seconds(CLOCK_THREAD_CPUTIME_ID);
    while (!stop) {
      if (auto r = chamber_driver.read()) {
        ++rep.chamber_reads;
      } else {
        ++rep.chamber_errors;
        note("chamber", r.error());
      }
      const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(1.0 / o.chamber_read_hz);
      while (!stop && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    chamber_cpu = cpu_seconds(CLOCK_THREAD_CPUTIME_ID) - cpu0;
  });

  std::vector<ImuPoint> points;
  points.reserve(static_cast<std::size_t>(o.duration_s * o.imu_rate_hz * 1.1) + 16);
  double imu_cpu = 0.0, time_sum2 = 0.0;
  std::uint64_t time_n = 0;
  std::thread imu_thread([&] {
    const double cpu0 = cpu_seconds(CLOCK_THREAD_CPUTIME_ID);
    ImuBatch batch;
    while (!stop) {
      batch.samples.clear();
      batch.temperatures.clear();
      if (auto r = imu_driver.poll(batch, std::chrono::milliseconds(50)); !r) {
        ++rep.imu_errors;
        note("imu", r.error());
      }
      for (const ImuSample& s : batch.samples) {
        const auto truth = imu.truth(s.sequence);
        if (!truth) continue;
        points.push_back({s.t_ns, truth->table_deg});
        // Past the first seconds, when the clock model has settled.
        if (imu_driver.clock_model().points > 20) {
          const double e = static_cast<double>(s.t_ns - truth->host_ns) / 1e3;
          time_sum2 += e * e;
          ++time_n;
          rep.imu_time_max_us = std::max(rep.imu_time_max_us, std::fabs(e));
        }
      }
      if (o.progress && !points.empty() && points.size() % static_cast<std::size_t>(10 * o.imu_rate_hz) < batch.samples.size())
        std::fprintf(stderr, "  %.0f s: %zu samples, %llu lost\n",
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count(), points.size(),
                     static_cast<unsigned long long>(imu_driver.counters().samples_lost));
    }
    imu_cpu = cpu_seconds(CLOCK_THREAD_CPUTIME_ID) - cpu0;
  });

  while (std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count() < o.duration_s)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  stop = true;
  table_thread.join();
  chamber_thread.join();
  imu_thread.join();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  rep.process_cpu_percent = 100.0 * (cpu_seconds(CLOCK_PROCESS_CPUTIME_ID) - process_cpu0) / wall;
  (void)table_driver.safe_stop();
  (void)chamber_driver.safe_stop();
  (void)imu_driver.safe_stop();

  rep.duration_s = wall;
  const ImuCounters c = imu_driver.counters();
  rep.imu_samples = c.samples_delivered;
  rep.imu_lost = c.samples_lost;
  rep.imu_gaps = c.sequence_gaps;
  rep.imu_crc_failures = c.crc_failures;
  rep.imu_malformed = c.malformed_frames;
  rep.imu_stalls = c.stalls;
  rep.imu_not_sent = imu.samples_not_sent();
  rep.physics_restarts = imu.physics_restarts();
  rep.table_clock_resets = table_driver.clock_model().resets;
  rep.imu_clock_resets = imu_driver.clock_model().resets;
  rep.imu_cpu_percent = 100.0 * imu_cpu / wall;
  rep.table_cpu_percent = 100.0 * table_cpu / wall;
  rep.chamber_cpu_percent = 100.0 * chamber_cpu / wall;

  // Alignment: the table angle at each IMU sample time, from the two bracketing table reads
  // (cubic Hermite with their rates), against the angle the physics had at the sample instant;
  // divided by the axis rate it is the time misalignment of the two streams.
  std::size_t j = 0;
  double sum2 = 0.0;
  std::vector<double> abs_err_us;
  abs_err_us.reserve(points.size());
  for (const ImuPoint& p : points) {
    while (j + 1 < reads.size() && reads[j + 1].t_ns <= p.t_ns) ++j;
    if (j + 1 >= reads.size() || reads[j].t_ns > p.t_ns) continue;
    const TableRead& a = reads[j];
    const TableRead& b = reads[j + 1];
    const double h = static_cast<double>(b.t_ns - a.t_ns) * 1e-9;
    if (h <= 0.0 || h > 3.0 / o.table_read_hz) continue;
    // The fastest-moving axis gives the best time resolution.
    std::size_t k = 0;
    for (std::size_t i = 1; i < 3; ++i)
      if (std::fabs(a.rate_dps[i]) > std::fabs(a.rate_dps[k])) k = i;
    if (std::fabs(a.rate_dps[k]) < 5.0 || std::fabs(b.rate_dps[k]) < 5.0) continue;
    const double s = static_cast<double>(p.t_ns - a.t_ns) * 1e-9 / h;
    const double angle = cubic_hermite(a.angle_deg[k], a.rate_dps[k], b.angle_deg[k], b.rate_dps[k], h, s);
    const double rate = a.rate_dps[k] + s * (b.rate_dps[k] - a.rate_dps[k]);
    const double err_us = (angle - p.table_deg[static_cast<Eigen::Index>(k)]) / rate * 1e6;
    sum2 += err_us * err_us;
    abs_err_us.push_back(std::fabs(err_us));
    rep.alignment_max_us = std::max(rep.alignment_max_us, std::fabs(err_us));
    ++rep.alignment_points;
  }
  if (rep.alignment_points > 0) {
    rep.alignment_rms_us = std::sqrt(sum2 / static_cast<double>(rep.alignment_points));
    const auto k99 = abs_err_us.begin() + static_cast<std::ptrdiff_t>(0.99 * static_cast<double>(abs_err_us.size() - 1));
    std::nth_element(abs_err_us.begin(), k99, abs_err_us.end());
    rep.alignment_p99_us = *k99;
  }
  if (time_n > 0) rep.imu_time_rms_us = std::sqrt(time_sum2 / static_cast<double>(time_n));
  return rep;
}

}  // namespace imucal::bench
