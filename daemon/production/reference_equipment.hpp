// The reference equipment's calibrations against a day (issue 35, deliverable 4): the one rule for
// which instrument (the rate table, the chamber, the survey of the site's g) is past its due date
// or due soon. The start check (an overdue instrument refuses a campaign's start unless an operator
// overrides it), the certificate (an instrument overdue on the day the run ended is marked so) and
// the live page's warning (GET /api/status) all judge with equipment_due; none of them compares
// dates itself. Pure: the day is the caller's (no clock here).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"

namespace imucal::daemon {

// How many days ahead a due date is announced.
inline constexpr std::int64_t kDueSoonDays = 7;

// One configured instrument judged on a day.
struct InstrumentDue {
  std::string instrument;        // the configuration's key: "table", "chamber" or "gravity"
  std::string title;             // "rate table", "climatic chamber", "gravity survey"
  std::string identity;          // "Acme Motion ATS-3, serial T-0815"; "by NGS, certificate G-17"
  std::string serial;            // the instrument's serial number (empty for the gravity survey)
  std::string certificate;       // its own certificate's number (empty: none configured)
  std::string calibration_due;   // "YYYY-MM-DD"
  std::int64_t due_in_days = 0;  // the due day less the day judged: 0 on the due day, negative after
  bool overdue = false;          // due before the day judged: out of calibration on that day
  bool due_soon = false;         // not overdue, due within kDueSoonDays of the day judged
};

// The day number (days since 1970-01-01, as date_day_number counts) of a Unix time in UTC.
std::int64_t utc_day(std::int64_t unix_ms);

// Every configured instrument (table, chamber, gravity, in that order; one the configuration does
// not name is left out) judged on `day`: overdue when its calibration_due is before `day` (an
// instrument may be used on its due day), due soon when not overdue and due at most kDueSoonDays
// after `day`.
std::vector<InstrumentDue> equipment_due(const ReferenceEquipment& equipment, std::int64_t day);

// One instrument's due date in words, the one place they are written (the daemon's refusals, the
// live page's banner and the override dialog in the browser all show these, web/js/equipment.mjs
// composes none): "the rate table (Acme Motion ATS-3, serial T-0815) was due for calibration on
// 2020-01-31" when overdue, "... is due for calibration on ..." otherwise ("a new survey" for the
// gravity survey).
std::string due_sentence(const InstrumentDue& d);
// The sentence as a line for a person, with how far the due day is: "The rate table (...) was due
// for calibration on 2020-01-31 (3 days ago).", "... (today).", "... (tomorrow).", "... (in 5 days).".
std::string due_line(const InstrumentDue& d);
// What follows for a start, after the lines of the instruments overdue or due soon: empty when
// none is; else the consequence of an overdue one (a start needs an operator's override), or of a
// due date passing.
std::string due_banner(const std::vector<InstrumentDue>& judged);

// The overdue ones of `judged` in words, for an operator: their due_sentence joined with "; ".
std::string overdue_text(const std::vector<InstrumentDue>& judged);

// What to say of the reference equipment, judged on `day` (utc_day of the run's end for a
// certificate, of today for the live page):
//   {"table": {make, model, serial, calibration_due, calibration_certificate, uncertainty, overdue} | null,
//    "chamber": ... | null,
//    "gravity": {surveyed_by, calibration_certificate, calibration_due, uncertainty, sigma_mps2, overdue} | null}
// calibration_certificate and uncertainty are null when not configured. The gravity survey's
// uncertainty is the 1-sigma the calibration uses for the site's g (earth::site_gravity_sigma_mps2),
// not a configured number. `with_days` (the live page's) adds due_in_days, due_soon and `text`
// (due_line) to each, and `banner` (due_banner; null when nothing is due soon or overdue) beside
// them.
nlohmann::json reference_equipment_json(const DaemonConfig& config, std::int64_t day, bool with_days);

}  // namespace imucal::daemon
