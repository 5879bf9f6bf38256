// Calibration certificates (issue 17, docs/api.md "Certificates", docs/daemon.md "Certificates"):
// numbers that never repeat on a site, and what a certificate states about the bench beside the
// campaign (its reference equipment, the site's gravity and how it was obtained).
//
// A number is PREFIX-YYYY-NNNNNN: the site's prefix (configuration), the year of issue and a
// site-wide sequence that never restarts (not even with the year). The sequence lives in a small
// file of its own, outside the data directory: a lab that starts a new data directory keeps
// counting. The file is replaced atomically (temporary file, fsync, rename) under an exclusive
// lock, so two daemons sharing it never take the same number.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"

namespace imucal::daemon {

class CertificateSequence {
 public:
  // `path`: the sequence file (certificate_sequence_path). Nothing is read until next().
  explicit CertificateSequence(std::string path);

  // Takes the next number: one more than the larger of the file's last number and `floor` (the
  // highest this daemon's database has issued, so that a sequence file restored from an old
  // backup cannot hand out a number again). Throws std::runtime_error naming the file when it
  // cannot be read or written: a certificate without a safe number is not issued. A crash
  // between taking a number and recording it leaves a gap, never a repeat.
  std::int64_t next(std::int64_t floor);
  // The last number taken (0 when the file does not exist yet).
  std::int64_t last() const;
  const std::string& path() const { return path_; }

 private:
  std::int64_t read_last() const;
  std::string path_;
  mutable std::mutex mutex_;  // one taker at a time in this process; the file lock for the rest
};

// "LAB-2026-000123" (at least six digits).
std::string certificate_number(const std::string& prefix, int year, std::int64_t sequence);

// What a certificate states about the bench, as configured when its number is issued (kept with
// the number, so that a certificate shows the same equipment when printed again later):
//   {"devices", "simulated",
//    "reference_equipment": reference_equipment_json (reference_equipment.hpp): the table, the
//                           chamber and the gravity survey with their certificates, uncertainties
//                           and due dates, each judged on the day the campaign ended (UTC):
//                           `overdue`, it was out of calibration when it was used,
//    "gravity": {"value_mps2", "sigma_mps2", "source": "configured" | "normal_gravity", "latitude_deg", "height_m"}}
// (Certificates issued before issue 35's reference equipment lack the gravity survey, the
// uncertainties and sigma_mps2: what was issued stays as it was.)
nlohmann::json certificate_bench_json(const DaemonConfig& config, std::int64_t campaign_ended_ms);

}  // namespace imucal::daemon
