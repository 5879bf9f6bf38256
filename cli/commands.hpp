// The subcommands of `imucal`, one file each in cli/ (README, "The command line"). main.cpp
// registers their options with CLI11 into these argument structs and runs the one given; each
// run_* returns the exit status and throws std::exception with a message for the operator.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

// Declared only: the heavy headers (the pipeline, the estimators) stay in the files that use them.
namespace imucal::plan {
struct Options;
struct OptimizeOptions;
}  // namespace imucal::plan
namespace imucal::daemon {
struct CampaignRunOptions;
}  // namespace imucal::daemon

namespace imucal::cli {

struct SimulateArgs {
  std::string program, imu = "ideal", db;
  double rate_hz = 1000, duration_s = 0, azimuth_deg = 0;
  std::uint64_t seed = 1;
  std::vector<double> r0_mm = {0, 0, 0};
  std::string chamber;                       // stage 2: a chamber profile drives the temperatures
  bool stabilise = false;
  std::vector<std::string> temp_faults;      // channel:kind:t0:t1[:jump_C]
  std::vector<double> chamber_reach_C;       // lo hi: what the chamber can reach (a fault)
  std::string table;                         // the table's certificate (formats.md `table`), a file
};

struct NavigateArgs {
  std::string db, model, out, summary_json;
  double interval_s = 1.0;
};

struct CalibrateArgs {
  std::string db, stage = "direct", model, out, frame = "instrument";
  int passes = 1;
  std::string report;                   // stage thermal: imucal-thermal-report/1
  int statics_per_cycle = 0;            // stage thermal: when the statics carry no cycle names
  double t_ref_C = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> range_C = {15.0, 35.0};
  bool keep_shape = false;              // stage thermal: fit only the constants, keep the polynomials
};

struct SimDevicesArgs {
  int table_port = 0, chamber_port = 0;
  std::string imu_socket, imu_link = "imucal-can", truth = "ideal", serial, config_file, framing = "fd";
  std::string table_dialect = "imucal-acl";
  double rate_hz = 1000.0;
  std::uint64_t seed = 1;
};

int run_simulate(const SimulateArgs& a);
int run_navigate(const NavigateArgs& a);
int run_calibrate(const CalibrateArgs& a);
int run_evaluate(const std::string& db_path, const std::vector<std::string>& models, const std::string& out_path);
int run_compare(const std::string& model_path, const std::string& truth_path, const std::string& json_out);
int run_sim_devices(const SimDevicesArgs& a);
int run_plan(const std::string& program_arg, const std::string& imu_path, const plan::Options& opt,
             const std::string& json_out);
int run_plan_optimize(const std::string& program_arg, const std::string& imu_path, const plan::OptimizeOptions& opt,
                      const std::string& target_arg, const std::string& program_out, const std::string& json_out);
int run_passwd();
int run_keygen(const std::string& out_path);
// key_path or fingerprint (not both): the lab's key; both empty: the key is not checked.
// imucal registry migrate DATA_DIR --to CONNINFO (cli/registry.cpp).
struct RegistryMigrateArgs {
  std::string data_dir, to;
  std::string config_file;    // the stand's imucald.json: its registry.stand and limits_file
  std::string stand;          // overrides the configuration's (default: the host's name)
  std::string limits_file;    // overrides the configuration's (default: DATA_DIR/limits.json)
  std::string operator_name;  // who migrates, in the lab's audit trail (default: the login name)
  bool dry_run = false;
};

int run_verify(const std::string& document_path, const std::string& key_path, const std::string& fingerprint);
// imucal audit verify DATA_DIR: 0 when the audit trail holds, 1 naming the first entry that does not.
int run_audit_verify(const std::string& data_dir);
// imucal audit verify --postgresql CONNINFO: the lab's chain, and each stand's chain it took in.
int run_audit_verify_postgresql(const std::string& conninfo);
int run_registry_migrate(const RegistryMigrateArgs& a);
// imucal registry init --to CONNINFO: the lab's registry's schema at this imucal's version.
int run_registry_init(const std::string& conninfo);
int run_export(const std::string& db_path, const std::string& dir);
int run_import(const std::string& dir, const std::string& db_path);
int run_campaign(const std::string& file, const daemon::CampaignRunOptions& options, bool json);

}  // namespace imucal::cli
