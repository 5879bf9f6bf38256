#include "daemon/run/suspenders.hpp"

#include <cmath>
#include <cstdio>

#include "core/number_text.hpp"

namespace imucal::daemon {

namespace {

// A device suspender: trips while its condition holds; clear when it does not (the settle time is
// the sequencer's: every suspender clear for settle_s).
class Simple final : public Suspender {
 public:
  using Check = std::optional<std::string> (*)(const DeviceReadings&);
  Simple(const char* name, std::string condition, std::string resume, Check check)
      : name_(name), condition_(std::move(condition)), resume_(std::move(resume)), check_(check) {}
  const char* name() const override { return name_; }
  std::string condition() const override { return condition_; }
  std::string resume_rule() const override { return resume_; }
  std::optional<std::string> trip(const DeviceReadings& r) override { return check_(r); }
  bool clear(const DeviceReadings& r) const override { return !check_(r); }

 private:
  const char* name_;
  std::string condition_, resume_;
  Check check_;
};

// The chamber out of its band for chamber_persist_s: a single noisy reading does not hold a run.
class ChamberOutOfBand final : public Suspender {
 public:
  explicit ChamberOutOfBand(const SuspenderSettings& s) : persist_s_(s.chamber_persist_s), settle_s_(s.settle_s) {}
  const char* name() const override { return "chamber-out-of-band"; }
  std::string condition() const override {
    return "the chamber's temperature outside the set point ± the campaign's tolerance for " + number_text(persist_s_) + " s";
  }
  std::string resume_rule() const override {
    return "back in band for " + number_text(settle_s_) + " s; the segment is redone from its start";
  }
  std::optional<std::string> trip(const DeviceReadings& r) override {
    if (!out_of_band(r)) {
      since_s_.reset();
      return std::nullopt;
    }
    if (!since_s_) since_s_ = r.now_s;
    if (r.now_s - *since_s_ < persist_s_) return std::nullopt;
    return "chamber out of band: " + celsius_text(r.chamber_C) + ", set point " + celsius_text(r.setpoint_C) + " ± " +
           celsius_text(r.tolerance_C);
  }
  bool clear(const DeviceReadings& r) const override { return !out_of_band(r); }
  void reset() override { since_s_.reset(); }

 private:
  static bool out_of_band(const DeviceReadings& r) {
    return r.chamber_connected && std::abs(r.chamber_C - r.setpoint_C) > r.tolerance_C;
  }
  double persist_s_, settle_s_;
  std::optional<double> since_s_;
};

class FramesMissing final : public Suspender {
 public:
  explicit FramesMissing(const SuspenderSettings& s) : timeout_s_(s.frame_timeout_s), settle_s_(s.settle_s) {}
  const char* name() const override { return "imu-frames-missing"; }
  std::string condition() const override { return "no IMU frame for " + number_text(timeout_s_) + " s"; }
  std::string resume_rule() const override {
    return "the IMU connected for " + number_text(settle_s_) + " s; the segment is redone from its start";
  }
  std::optional<std::string> trip(const DeviceReadings& r) override {
    if (r.now_s - r.last_frame_s <= timeout_s_) return std::nullopt;
    char text[160];
    std::snprintf(text, sizeof text, "IMU frames missing: none for %.2f s", r.now_s - r.last_frame_s);
    return text;
  }
  // Before the segment starts there are no frames to miss: the link must be up.
  bool clear(const DeviceReadings& r) const override { return r.imu_connected; }

 private:
  double timeout_s_, settle_s_;
};

}  // namespace

Suspenders::Suspenders(const SuspenderSettings& s) {
  const std::string settle = "clear for " + number_text(s.settle_s) + " s; the segment is redone from its start";
  // Recording first: a run that cannot record must hold whatever the devices do.
  list_.push_back(std::make_unique<Simple>(
      "recorder", "the run file cannot be written, or its writer falls behind a device that cannot wait",
      "the recorder has committed everything it holds; the segment holding the first frame lost is redone",
      [](const DeviceReadings& r) -> std::optional<std::string> {
        if (r.recorder_problem.empty()) return std::nullopt;
        return r.recorder_problem;
      }));
  list_.push_back(std::make_unique<Simple>(
      "imu-frames-bad", "frames not finite, out of time order, or dropped by the recorder", settle,
      [](const DeviceReadings& r) -> std::optional<std::string> {
        if (r.frame_problem.empty()) return std::nullopt;
        return r.frame_problem;
      }));
  list_.push_back(std::make_unique<Simple>("table-disconnected", "the table controller does not answer", settle,
                                           [](const DeviceReadings& r) -> std::optional<std::string> {
                                             if (r.table_connected) return std::nullopt;
                                             return std::string("table disconnected");
                                           }));
  list_.push_back(std::make_unique<Simple>("table-fault", "the table controller reports a drive fault", settle,
                                           [](const DeviceReadings& r) -> std::optional<std::string> {
                                             if (r.table_fault.empty()) return std::nullopt;
                                             return "table fault: " + r.table_fault;
                                           }));
  list_.push_back(std::make_unique<Simple>("chamber-disconnected", "the chamber controller does not answer", settle,
                                           [](const DeviceReadings& r) -> std::optional<std::string> {
                                             if (r.chamber_connected) return std::nullopt;
                                             return std::string("chamber disconnected");
                                           }));
  list_.push_back(std::make_unique<ChamberOutOfBand>(s));
  list_.push_back(std::make_unique<FramesMissing>(s));
}

std::optional<Trip> Suspenders::trip(const DeviceReadings& r) {
  // Every one sees the readings (the chamber's persistence counts even when another trips first).
  std::optional<Trip> first;
  for (auto& s : list_)
    if (auto why = s->trip(r); why && !first) first = Trip{s->name(), std::move(*why)};
  return first;
}

bool Suspenders::clear(const DeviceReadings& r) const {
  for (const auto& s : list_)
    if (!s->clear(r)) return false;
  return true;
}

void Suspenders::reset() {
  for (auto& s : list_) s->reset();
}

nlohmann::json Suspenders::describe() const {
  nlohmann::json out = nlohmann::json::array();
  for (const auto& s : list_)
    out.push_back({{"name", s->name()}, {"condition", s->condition()}, {"severity", s->severity()},
                   {"resume", s->resume_rule()}});
  return out;
}

}  // namespace imucal::daemon
