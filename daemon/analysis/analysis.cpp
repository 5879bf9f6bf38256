#include "daemon/analysis/analysis.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <archive.h>
#include <archive_entry.h>

#include "core/units.hpp"
#include "estimators/evaluate.hpp"
#include "estimators/noise.hpp"
#include "estimators/thermal.hpp"
#include "pipeline/pipeline.hpp"
#include "storage/bundle.hpp"
#include "storage/run_db.hpp"

namespace imucal::daemon {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

storage::RunDb open_run(const std::string& run_path) {
  return storage::RunDb::open(run_path, storage::OpenMode::Read);
}

// The files as one tar archive (POSIX pax, which is plain ustar while names are short), written by
// libarchive under `path`; `top_dir` prefixes every name. `progress`: the fraction of the bytes
// copied, once a buffer.
void write_tar(const std::string& path, const std::string& top_dir, const std::vector<fs::path>& files,
               const AnalysisProgress& progress) {
  struct ArchiveFree {
    void operator()(archive* a) const noexcept { archive_write_free(a); }
  };
  struct EntryFree {
    void operator()(archive_entry* e) const noexcept { archive_entry_free(e); }
  };
  const std::unique_ptr<archive, ArchiveFree> a(archive_write_new());
  if (!a) throw std::runtime_error("tar " + path + ": out of memory");
  auto check = [&](la_ssize_t rc, const std::string& what) {
    if (rc < ARCHIVE_OK) {
      const char* why = archive_error_string(a.get());
      throw std::runtime_error("tar " + path + ": " + what + ": " + (why != nullptr ? why : "failed"));
    }
  };
  check(archive_write_set_format_pax_restricted(a.get()), "setting the format");
  check(archive_write_open_filename(a.get(), path.c_str()), "opening");
  const auto mtime = std::chrono::duration_cast<std::chrono::seconds>(
                         std::chrono::system_clock::now().time_since_epoch()).count();
  std::vector<char> buf(1 << 16);
  std::uintmax_t total_bytes = 1, done_bytes = 0;
  for (const fs::path& file : files) total_bytes += fs::file_size(file);
  for (const fs::path& file : files) {
    const auto size = fs::file_size(file);
    const std::string name = top_dir + "/" + file.filename().string();
    const std::unique_ptr<archive_entry, EntryFree> entry(archive_entry_new());
    archive_entry_set_pathname(entry.get(), name.c_str());
    archive_entry_set_size(entry.get(), static_cast<la_int64_t>(size));
    archive_entry_set_filetype(entry.get(), AE_IFREG);
    archive_entry_set_perm(entry.get(), 0644);
    archive_entry_set_mtime(entry.get(), static_cast<time_t>(mtime), 0);
    check(archive_write_header(a.get(), entry.get()), "the header of " + name);
    std::ifstream in(file, std::ios::binary);
    if (!in) throw std::runtime_error("tar " + path + ": cannot read " + file.string());
    std::uintmax_t copied = 0;
    while (in) {
      in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
      const auto n = in.gcount();
      if (n <= 0) break;
      check(archive_write_data(a.get(), buf.data(), static_cast<std::size_t>(n)), "writing " + name + " (disk full?)");
      copied += static_cast<std::uintmax_t>(n);
      done_bytes += static_cast<std::uintmax_t>(n);
      if (progress) progress(static_cast<double>(done_bytes) / static_cast<double>(total_bytes));
    }
    if (copied != size) throw std::runtime_error("tar " + path + ": " + file.string() + " changed while being archived");
  }
  check(archive_write_close(a.get()), "closing (disk full?)");
}

// One stage of the calibration pipeline on the finished run, as `imucal calibrate --stage X`
// runs it; a stage the run cannot support is NotAvailable with the stage's reason.
pipeline::Outcome stage_on_run(const storage::RunDb& db, pipeline::Stage stage, const ImuModel& input,
                               const std::string& what, const AnalysisProgress& progress) {
  const RecordingMeta meta = db.meta();
  const pipeline::RunDbSource run(db);
  const pipeline::ProgressSource source(run, pipeline::end_of_program_s(meta), progress);
  pipeline::Outcome o = pipeline::run_to_end(meta, source, {stage}, true, input).front();
  if (o.status != pipeline::Status::Done) throw NotAvailable("not available for this run: " + what + o.message);
  return o;
}

// A stage that is done has its estimator's result; its absence is an internal error naming it.
template <class Result>
const Result& expect_result(const pipeline::Outcome& o, const char* what) {
  const Result* r = o.result_as<Result>();
  if (!r) throw std::logic_error(std::string("internal error: ") + what + " is missing");
  return *r;
}

}  // namespace

Recalibration calibrate_again(const std::string& run_path, const std::vector<std::string>& estimators,
                              const ImuModel& start, std::optional<double> gravity_mps2,
                              const AnalysisProgress& progress) {
  const storage::RunDb db = open_run(run_path);
  RecordingMeta meta = db.meta();
  meta.site.gravity_mps2 = gravity_mps2;
  std::vector<pipeline::Stage> stages;
  for (const std::string& name : estimators)
    if (const auto stage = pipeline::stage_of_estimator(name)) stages.push_back(*stage);
  if (stages.empty()) throw NotAvailable("the campaign ran no calibration stage: there is nothing to calibrate again");
  const pipeline::RunDbSource run(db);
  const pipeline::ProgressSource source(run, pipeline::end_of_program_s(meta), progress);
  pipeline::Calibration c = pipeline::calibration_of(pipeline::run_to_end(meta, source, stages, true, start));
  return {std::move(c.reports), std::move(c.model)};
}

int prune_exports(const std::string& dir, const std::string& keep, std::int64_t max_bytes) {
  struct Bundle {
    fs::path path;
    fs::file_time_type written;
    std::uintmax_t bytes;
  };
  std::vector<Bundle> bundles;
  std::error_code ec;
  std::uintmax_t total = 0;
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
    if (e.path().extension() != ".tar" || !e.is_regular_file(ec)) continue;
    const Bundle b{e.path(), e.last_write_time(ec), e.file_size(ec)};
    if (ec) continue;
    total += b.bytes;
    if (!fs::equivalent(b.path, keep, ec)) bundles.push_back(b);
  }
  std::sort(bundles.begin(), bundles.end(), [](const Bundle& a, const Bundle& b) { return a.written < b.written; });
  int removed = 0;
  for (const Bundle& b : bundles) {
    if (total <= static_cast<std::uintmax_t>(std::max<std::int64_t>(0, max_bytes))) break;
    if (fs::remove(b.path, ec)) {
      total -= b.bytes;
      ++removed;
    }
  }
  return removed;
}

json allan_from_run(const std::string& run_path, const AnalysisProgress& progress) {
  const storage::RunDb db = open_run(run_path);
  const pipeline::Outcome o = stage_on_run(db, pipeline::Stage::Noise, ImuModel{}, "the Allan deviation: ", progress);
  const noise::Result& r = expect_result<noise::Result>(o, "the noise stage's result");
  json out = json::parse(r.curves_json());
  for (const char* c : {"gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"}) {
    out[c].erase("psd");  // the PSD is not plotted; keep the answer small
    out[c].erase("psd_freq_hz");
  }
  json arw = json::array(), vrw = json::array(), bi_g = json::array(), bi_a = json::array();
  for (int c = 0; c < 3; ++c) {
    arw.push_back(r.channel[c].white * units::kRadToDeg * 60.0);  // rad/sqrt(s) -> deg/sqrt(h)
    vrw.push_back(r.channel[c + 3].white * 60.0);                 // (m/s)/sqrt(s) -> (m/s)/sqrt(h)
    bi_g.push_back(r.channel[c].bias_instability > 0 ? json(r.channel[c].bias_instability * units::kRadpsToDph)
                                                     : json(nullptr));
    bi_a.push_back(r.channel[c + 3].bias_instability > 0 ? json(r.channel[c + 3].bias_instability) : json(nullptr));
  }
  out["arw_deg_rth"] = arw;
  out["vrw_mps_rth"] = vrw;
  out["bias_instability_dph"] = bi_g;
  out["bias_instability_mps2"] = bi_a;
  out["longest_static_s"] = r.longest_static_s;
  out["total_static_s"] = r.total_static_s;
  out["notes"] = r.notes;
  return out;
}

json thermal_from_run(const std::string& run_path, const ImuModel& input, const AnalysisProgress& progress) {
  const storage::RunDb db = open_run(run_path);
  const pipeline::Outcome o = stage_on_run(db, pipeline::Stage::Thermal, input, "the thermal plots: ", progress);
  const thermal::Result& r = expect_result<thermal::Result>(o, "the thermal stage's result");
  const json report = json::parse(r.report_json);
  // report.plots: {"columns": [...], "series": {coefficient: [[row], ...]}} (docs/thermal.md).
  const json& plots = report.at("plots");
  std::map<std::string, std::size_t> col;
  for (std::size_t i = 0; i < plots.at("columns").size(); ++i) col[plots["columns"][i].get<std::string>()] = i;
  json coefficients = json::object();
  for (const auto& [name, rows] : plots.at("series").items()) {
    json c = {{"T_C", json::array()}, {"before", json::array()}, {"after", json::array()}, {"truth", json::array()}};
    for (const auto& row : rows) {
      c["T_C"].push_back(row.at(col.at("T_C")));
      c["before"].push_back(row.at(col.at("estimate")));
      c["after"].push_back(row.at(col.at("compensated")));
      c["truth"].push_back(row.at(col.at("truth")));
    }
    coefficients[name] = c;
  }
  return {{"T_ref_C", report.value("T_ref_C", 0.0)},
          {"cycles_total", r.cycles_total},
          {"cycles_used", r.cycles_used},
          {"residual_source", report.value("residual_source", "")},
          {"before", report.value("before", json::object())},
          {"residual", report.value("residual", json::object())},
          {"notes", r.notes},
          {"coefficients", coefficients}};
}

json evaluation_from_run(const std::string& run_path, const std::vector<Variant>& variants,
                         const AnalysisProgress& progress) {
  const storage::RunDb db = open_run(run_path);
  const RecordingMeta meta = db.meta();
  bool judged = false;
  for (const SegmentInfo& s : meta.segments) judged = judged || s.kind == "tilt" || s.kind == "coning";
  if (!judged)
    throw NotAvailable("not available for this run: the Schuler test needs the tilt and coning segments of program "
                       "'evaluate'");
  json out = {{"variants", json::array()}};
  const pipeline::RunDbSource run(db);
  const double n = static_cast<double>(std::max<std::size_t>(1, variants.size()));
  for (std::size_t k = 0; k < variants.size(); ++k) {
    const Variant& v = variants[k];
    // Each variant reads the run once: its share of the progress is 1/n.
    const pipeline::ProgressSource source(run, pipeline::end_of_program_s(meta), progress, static_cast<double>(k) / n,
                                          1.0 / n);
    const evaluate::Result r = pipeline::evaluate_recording(meta, source, v.model);
    json segments = json::array();
    for (const auto& s : r.segments) {
      json speed = json::array();
      for (std::size_t i = 0; i < s.t_s.size(); ++i) speed.push_back(std::hypot(s.ve_mps[i], s.vn_mps[i]));
      segments.push_back({{"name", s.name}, {"kind", s.kind}, {"t0_s", s.t0_s}, {"t1_s", s.t1_s},
                          {"schuler_amplitude_mps", s.amplitude_mps},
                          {"implied_accel_error_mps2", s.implied_accel_error_mps2},
                          {"implied_gyro_drift_dph", s.implied_gyro_drift_radps * units::kRadpsToDph},
                          {"max_velocity_error_mps", s.max_velocity_error_mps},
                          {"max_position_error_m", s.max_position_error_m},
                          {"time_s", s.t_s},
                          {"velocity_error_e_mps", s.ve_mps},
                          {"velocity_error_n_mps", s.vn_mps},
                          {"velocity_error_mps", speed}});
    }
    out["variants"].push_back({{"name", v.name},
                               {"source", v.source},
                               {"tilt_schuler_amplitude_mps", r.tilt_amplitude_mps},
                               {"coning_schuler_amplitude_mps", r.coning_amplitude_mps},
                               {"implied_accel_error_mps2", r.implied_accel_error_mps2},
                               {"implied_gyro_drift_dph", r.implied_gyro_drift_radps * units::kRadpsToDph},
                               {"segments", segments}});
  }
  return out;
}

std::optional<ImuModel> truth_of_run(const std::string& run_path) {
  const storage::RunDb db = open_run(run_path);
  const RecordingMeta meta = db.meta();
  if (meta.truth_json.empty()) return std::nullopt;
  return imu_model_from_json_text(meta.truth_json, "the run's truth");
}

std::string imu_serial_of_run(const std::string& run_path) { return open_run(run_path).meta().imu_serial; }

void write_recording_tar(const std::string& run_path, const std::string& tar_path, const std::string& top_dir,
                         const AnalysisProgress& progress) {
  // Writing frames.csv (every double formatted) takes about four times as long as copying the
  // files into the tar file: the shares of the progress.
  constexpr double kCsvShare = 0.8;
  const auto share = [&progress](double from, double width) -> AnalysisProgress {
    if (!progress) return {};
    return [&progress, from, width](double fraction) { progress(from + width * fraction); };
  };
  const fs::path work = fs::path(tar_path + ".work");
  const std::string partial = tar_path + ".partial";
  std::error_code ec;
  fs::remove_all(work, ec);
  try {
    const fs::path dir = work / top_dir;
    {
      const storage::RunDb db = open_run(run_path);
      storage::export_bundle(db, dir.string(), share(0.0, kCsvShare));
    }
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(dir))
      if (e.is_regular_file()) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    write_tar(partial, top_dir, files, share(kCsvShare, 1.0 - kCsvShare));
    fs::rename(partial, tar_path);
  } catch (...) {
    // A failed or cancelled export leaves no half bundle (as large as the bundle) on the disk.
    fs::remove(partial, ec);
    fs::remove_all(work, ec);
    throw;
  }
  fs::remove_all(work, ec);
}

}  // namespace imucal::daemon
