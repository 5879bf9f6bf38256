// imucal: the command line. A thin shell over the libraries: the options of every subcommand,
// registered here with CLI11, and the subcommands themselves, one file each in cli/.
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bench/storage_bench.hpp"
#include "cli/commands.hpp"
#include "core/units.hpp"
#include "daemon/campaign_runner.hpp"
#include "daemon/config/command_line.hpp"
#include "pipeline/pipeline.hpp"
#include "core/table_json.hpp"
#include "plan/optimize.hpp"
#include "plan/plan.hpp"
#include "signing/signing.hpp"

using namespace imucal;

int main(int argc, char** argv) {
  CLI::App app{"imucal: calibration of strapdown IMUs on a three-axis table", "imucal"};
  app.require_subcommand(1);

  cli::SimulateArgs sim_args;
  auto* sim = app.add_subcommand("simulate", "Simulate a motion program with a truth IMU into a run database");
  sim->add_option("--program", sim_args.program, "built-in program name or a program JSON file")->required();
  sim->add_option("--imu", sim_args.imu, "truth imucal-imu-model/1 JSON, or 'ideal'")->capture_default_str();
  sim->add_option("--db", sim_args.db, "output run database (must not exist)")->required();
  sim->add_option("--rate", sim_args.rate_hz, "IMU rate, Hz")->capture_default_str()->check(CLI::PositiveNumber);
  sim->add_option("--seed", sim_args.seed, "noise seed")->capture_default_str();
  sim->add_option("--duration", sim_args.duration_s, "stop after this many seconds (0: whole program)")
      ->check(CLI::NonNegativeNumber);
  sim->add_option("--azimuth", sim_args.azimuth_deg, "middle-axis azimuth, deg clockwise from North")
      ->capture_default_str();
  sim->add_option("--chamber", sim_args.chamber,
                  "chamber profile (built-in thermal, thermal-short, or a JSON file): temperatures and the truth's "
                  "thermal section drive the run");
  sim->add_flag("--stabilise", sim_args.stabilise, "with --chamber: the IMU's own thermal stabilisation (relay heater at 55 C: 0.4 C range, 16-30 min control cycle)");
  sim->add_option("--temp-fault", sim_args.temp_faults,
                  "with --chamber: a logged-temperature fault channel:kind:t0_s[:t1_s[:jump_C]] (kind stuck, jump, "
                  "missing; channel gx..az, gx1..gz8, chamber, all)");
  sim->add_option("--chamber-reach-C", sim_args.chamber_reach_C, "with --chamber: the lowest and highest air "
                  "temperature the chamber can reach")->expected(2);
  sim->add_option("--r0-mm", sim_args.r0_mm, "IMU origin from the axis intersection, platform frame, mm")
      ->expected(3);
  sim->add_option("--table", sim_args.table,
                  "the table's own errors: a JSON file holding the `table` object of formats.md (geometry, sigma, "
                  "certificate) or a recording's meta.json; the table moves with them and the run records them")
      ->check(CLI::ExistingFile);

  cli::NavigateArgs nav_args;
  auto* navc = app.add_subcommand("navigate", "Free-inertial navigation of a run against the table reference");
  navc->add_option("--db", nav_args.db, "run database")->required()->check(CLI::ExistingFile);
  navc->add_option("--model", nav_args.model, "imucal-imu-model/1 to compensate with (default: none)")
      ->check(CLI::ExistingFile);
  navc->add_option("--out", nav_args.out, "CSV of the horizontal errors over time")->required();
  navc->add_option("--summary-json", nav_args.summary_json, "summary (duration, max errors) as JSON");
  navc->add_option("--interval", nav_args.interval_s, "CSV row interval, s")->capture_default_str()->check(
      CLI::PositiveNumber);

  std::string exp_db, exp_dir;
  auto* exp = app.add_subcommand("export", "Write a run as an imucal-recording/1 bundle");
  exp->add_option("--db", exp_db, "run database")->required()->check(CLI::ExistingFile);
  exp->add_option("--out", exp_dir, "output folder")->required();

  std::string imp_dir, imp_db;
  auto* imp = app.add_subcommand("import", "Read an imucal-recording/1 bundle into a run database");
  imp->add_option("dir", imp_dir, "bundle folder (meta.json, frames.csv)")->required()->check(CLI::ExistingDirectory);
  imp->add_option("--db", imp_db, "output run database (must not exist)")->required();

  cli::CalibrateArgs cal_args;
  auto* cal = app.add_subcommand("calibrate", "Estimate the IMU model from a stored run");
  cal->add_option("--db", cal_args.db, "run database")->required()->check(CLI::ExistingFile);
  // The stages as the pipeline names them, in its order: one list for the check and the help.
  std::vector<std::string> stage_choices;
  std::string stage_help;
  for (const pipeline::StageDescriptor& n : pipeline::stage_registry()) {
    stage_choices.emplace_back(n.name);
    stage_help += std::string(n.name) + ", ";
  }
  stage_choices.emplace_back("all");
  cal->add_option("--stage", cal_args.stage, stage_help + "or all")->capture_default_str()->check(CLI::IsMember(stage_choices));
  cal->add_option("--report", cal_args.report,
                  "stage thermal, rate-steps, warm-up or repeatability: write the stage's report (thermal: residuals, "
                  "degrees, plots; rate-steps: every figure per gyro and rate; warm-up: every channel's transient and "
                  "the bins; repeatability: every channel's figure and each power-on's mean) here");
  cal->add_option("--statics-per-cycle", cal_args.statics_per_cycle,
                  "stage thermal: statics per table cycle, for a run whose statics are not named cycle-NNN/...");
  cal->add_option("--t-ref-C", cal_args.t_ref_C, "stage thermal: reference temperature (default: middle of the data)");
  cal->add_option("--range-C", cal_args.range_C, "stage thermal: the range the run was to cover, C")->expected(2);
  cal->add_flag("--keep-shape", cal_args.keep_shape,
                "stage thermal: keep the model's polynomials and fit only its constants to this run");
  cal->add_option("--model", cal_args.model, "model to start from; its other coefficients are carried over")
      ->check(CLI::ExistingFile);
  cal->add_option("--out", cal_args.out, "output imucal-imu-model/1 JSON")->required();
  cal->add_option("--frame", cal_args.frame, "instrument or body")->capture_default_str()->check(
      CLI::IsMember({"instrument", "body"}));

  cal->add_option("--passes", cal_args.passes, "stage navigation: passes over the recording, each seeded by the last")
      ->capture_default_str()
      ->check(CLI::Range(1, 10));

  std::string eval_db, eval_out;
  std::vector<std::string> eval_models;
  auto* ev = app.add_subcommand("evaluate", "Judge models by free-inertial navigation on an evaluate run (Schuler test)");
  ev->add_option("--db", eval_db, "run of the evaluate program")->required()->check(CLI::ExistingFile);
  ev->add_option("--model", eval_models, "MODEL.json or NAME=MODEL.json; repeat to compare variants (first = baseline)")
      ->required();
  ev->add_option("--out", eval_out, "report JSON")->required();

  imucal::daemon::CampaignRunOptions camp_opts;
  std::string camp_file;
  double camp_time_scale = -1.0;
  bool camp_json = false;
  auto* camp = app.add_subcommand("campaign", "Campaigns through the daemon's sequencer, in-process");
  camp->require_subcommand(1);
  auto* camp_run = camp->add_subcommand(
      "run", "Run a whole campaign on the simulated bench in accelerated time (sequencer, recorder, estimators)");
  camp_run->add_option("file", camp_file, "campaign JSON (docs/api.md, \"Campaign JSON\")")->required()->check(
      CLI::ExistingFile);
  camp_run->add_option("--data-dir", camp_opts.data_dir, "data directory for the daemon database and the run file")
      ->capture_default_str();
  camp_run->add_option("--config", camp_opts.config_file, "imucald configuration (limits, site)")->check(CLI::ExistingFile);
  camp_run->add_option("--model-out", camp_opts.model_out, "write the resulting imucal-imu-model/1 here");
  camp_run->add_option("--time-scale", camp_time_scale, "program seconds per wall second (default: the campaign's, "
                                                        "else as fast as possible)")
      ->check(CLI::NonNegativeNumber);
  camp_run->add_flag("--json", camp_json, "print the summary as one JSON object");
  std::string camp_override;
  auto* camp_override_opt = camp_run->add_option(
      "--override-overdue", camp_override,
      "start although reference equipment in --config is past its due date, saying why (kept in the audit trail "
      "and stated on the run's certificate)");
  camp_run->add_option("--operator", camp_opts.operator_name,
                       "who runs it, for the audit trail and an override (default: the login name)");

  std::string cmp_model, cmp_truth, cmp_json;
  auto* cmp = app.add_subcommand("compare", "Compare a calibration result with the truth of a simulated run");
  cmp->add_option("model", cmp_model, "estimated imucal-imu-model/1")->required()->check(CLI::ExistingFile);
  cmp->add_option("truth", cmp_truth, "truth imucal-imu-model/1 (put in the body frame when the model is)")
      ->required()
      ->check(CLI::ExistingFile);
  cmp->add_option("--json", cmp_json, "the table as JSON");

  cli::SimDevicesArgs simdev_args;
  auto* simdev = app.add_subcommand(
      "sim-devices", "Run the simulated table controller, chamber controller and IMU standalone on real addresses "
                     "and print the imucald devices configuration that reaches them (until SIGINT/SIGTERM)");
  simdev->add_option("--table-port", simdev_args.table_port, "TCP port of the table controller on 127.0.0.1 (0: any free)")
      ->capture_default_str()
      ->check(CLI::Range(0, 65535));
  simdev->add_option("--table-dialect", simdev_args.table_dialect,
                     "the table controller's language (imucal-acl or an imucal-table-dialect/1 file)")
      ->capture_default_str();
  simdev->add_option("--chamber-port", simdev_args.chamber_port,
                     "Modbus TCP port of the chamber controller on 127.0.0.1 (0: any free)")
      ->capture_default_str()
      ->check(CLI::Range(0, 65535));
  simdev->add_option("--imu-socket", simdev_args.imu_socket,
                     "Unix SOCK_SEQPACKET socket path a CAN IMU listens on (CAN frame images; a new simulated IMU for "
                     "each connection)");
  simdev->add_option("--imu-link", simdev_args.imu_link,
                     "the IMU's link description (imucal-can, kvh-1750, kvh-1775-b or an imucal-imu-link/1 file); a "
                     "serial one is served on a pseudo-terminal")
      ->capture_default_str();
  simdev->add_option("--rate-hz", simdev_args.rate_hz, "IMU sample rate, Hz")->capture_default_str()->check(
      CLI::Range(1.0, 100000.0));
  simdev->add_option("--framing", simdev_args.framing, "fd or classic (at most 200 Hz)")
      ->capture_default_str()
      ->check(CLI::IsMember({"fd", "classic"}));
  simdev->add_option("--seed", simdev_args.seed, "noise seed of the simulated IMU")->capture_default_str();
  simdev->add_option("--truth", simdev_args.truth, "the simulated IMU's imucal-imu-model/1 JSON, or 'ideal'")
      ->capture_default_str();
  simdev->add_option("--serial", simdev_args.serial, "the IMU serial in the printed configuration (default SIM-DEVICES-SEED)");
  simdev->add_option("--config", simdev_args.config_file,
                     "imucald configuration whose site, table limits and chamber defaults the devices take")
      ->check(CLI::ExistingFile);

  std::string plan_program, plan_imu, plan_json;
  plan::Options plan_opt;
  double plan_table_attitude_arcsec = plan_opt.settings.navigation.attitude_noise_rad * units::kRadToArcsec;
  auto* planc = app.add_subcommand(
      "plan", "Predict the 1-sigma of every coefficient a program will give, before the table moves (the program "
              "simulated with the IMU's noise through the calibration pipeline)");
  planc->add_option("--program", plan_program, "built-in program name or a program JSON file")->required();
  planc->add_option("--imu", plan_imu, "the unit's imucal-imu-model/1 with its noise section")
      ->required()
      ->check(CLI::ExistingFile);
  planc->add_option("--rate", plan_opt.rate_hz, "IMU rate, Hz")->capture_default_str()->check(CLI::PositiveNumber);
  planc->add_option("--seed", plan_opt.seed, "noise seed of the simulation")->capture_default_str();
  // The table's reference accuracy, as stage 3 is told it (docs/stage3.md): it bounds the delays
  // and proof masses the program can determine.
  planc->add_option("--table-attitude-arcsec", plan_table_attitude_arcsec,
                    "1-sigma of the attitude the table's encoders give, arcsec")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  planc->add_option("--table-velocity-mps", plan_opt.settings.navigation.velocity_noise_mps,
                    "1-sigma of the table's reference velocity, m/s")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  planc->add_option("--table-position-m", plan_opt.settings.navigation.position_noise_m,
                    "1-sigma of the table's reference position, m")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  // The table's certificate and the site's g: the bench sources of stage 1's budget.
  std::string plan_table;
  double plan_table_sigma_arcsec = 0.0, plan_gravity_sigma_mps2 = 0.0;
  planc->add_option("--table", plan_table,
                    "the table's certificate: a JSON file holding the `table` object of formats.md or a recording's "
                    "meta.json; its sigma enters stage 1's budget and the table requirements")
      ->check(CLI::ExistingFile);
  planc->add_option("--table-sigma-arcsec", plan_table_sigma_arcsec,
                    "instead of --table: a certificate of this 1-sigma for every tilt, axis and encoder harmonic (1, 2)")
      ->check(CLI::PositiveNumber)
      ->excludes("--table");
  planc->add_option("--gravity-sigma-mps2", plan_gravity_sigma_mps2,
                    "1-sigma of the site's g (default: 3e-4, normal gravity; 1e-6 for a measured g)")
      ->check(CLI::NonNegativeNumber);
  planc->add_option("--json", plan_json, "write the prediction (imucal-plan/1), or with --optimize the search, here");
  bool plan_optimize = false;
  std::string plan_target = "seed", plan_program_out;
  plan::OptimizeOptions plan_search;
  planc->add_flag("--optimize", plan_optimize,
                  "search the program's swing periods and oscillation cycles for the shortest that meets the targets");
  planc->add_option("--target", plan_target, "with --optimize: 'seed' (the seed's stage-3 figures) or a JSON file "
                                             "{\"gyro.bias_dph\": 0.001, ...}")
      ->capture_default_str();
  planc->add_option("--budget-s", plan_search.budget_s, "with --optimize: wall time for the search, s")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  planc->add_option("--write-program", plan_program_out, "with --optimize: write the best program here");

  auto* passwd = app.add_subcommand(
      "passwd", "Print the hash of a password (read from standard input) for a user's password_hash in imucald's "
                "configuration");

  std::string keygen_out;
  auto* keygen = app.add_subcommand(
      "keygen", "Make the lab's Ed25519 key for signing certificates and test reports: FILE (the secret key, mode "
                "0600) and FILE.pub (the public key); prints its fingerprint (docs/signing.md)");
  keygen->add_option("--out", keygen_out, "the key file to write (must not exist, nor FILE.pub)")->required();

  std::string verify_file, verify_key, verify_fingerprint;
  auto* verify = app.add_subcommand(
      "verify", "Verify a signed certificate or test report offline: its format, content hash, signature and that "
                "the key is the lab's; exit status 0 only when all four pass (docs/signing.md)");
  verify->add_option("file", verify_file, "the signed JSON document (imucal-signed/1)")
      ->required()
      ->check(CLI::ExistingFile);
  auto* verify_key_option =
      verify->add_option("--key", verify_key, "the lab's public key (LAB.pub, from imucal keygen)")->check(
          CLI::ExistingFile);
  verify->add_option("--fingerprint", verify_fingerprint,
                     "the lab's key fingerprint (ed25519:xxxx:..., as imucal keygen prints it)")
      ->excludes(verify_key_option)
      ->check(CLI::Validator(
          [](std::string& text) {
            try {
              signing::parse_fingerprint(text);
              return std::string();
            } catch (const std::invalid_argument& e) {
              return std::string(e.what());
            }
          },
          "FINGERPRINT"));

  auto* audit = app.add_subcommand("audit", "The audit trail of an imucald data directory or a lab's registry: audit verify");
  audit->require_subcommand(1);
  std::string audit_dir, audit_postgresql;
  auto* audit_verify = audit->add_subcommand(
      "verify", "Check the audit trail of DATA_DIR, or of the lab's PostgreSQL registry, offline: every entry's "
                "hash, its link to the one before, no gap, the recorded last entry; names the first entry that does "
                "not hold (exit status 1)");
  auto* audit_dir_opt = audit_verify->add_option("data_dir", audit_dir, "imucald's data directory (holding imucald.db)");
  audit_verify
      ->add_option("--postgresql", audit_postgresql,
                   "instead of DATA_DIR: the lab's registry, a libpq connection string (as registry.postgresql); "
                   "also checks each stand's chain moved in by imucal registry migrate")
      ->excludes(audit_dir_opt);

  auto* registry = app.add_subcommand("registry", "The lab's registry (issue 38): registry init, registry migrate");
  registry->require_subcommand(1);
  std::string init_to;
  auto* registry_init = registry->add_subcommand(
      "init", "Create the lab's PostgreSQL registry's schema, or migrate it to this imucal's version, as its owner "
              "role (stands connect with a role that may not)");
  registry_init->add_option("--to", init_to, "the lab's registry: a libpq connection string of its owner role")
      ->required();
  cli::RegistryMigrateArgs migrate_args;
  auto* migrate = registry->add_subcommand(
      "migrate", "Move a stand's registry (certificates, pages, overdue overrides, calibrations, limits, audit trail) "
                 "from its data directory into the lab's PostgreSQL registry; imucald must be stopped there. Copies "
                 "nothing twice");
  migrate->add_option("data_dir", migrate_args.data_dir, "the stand's data directory (holding imucald.db)")->required();
  migrate->add_option("--to", migrate_args.to, "the lab's registry: a libpq connection string (as registry.postgresql)")
      ->required();
  migrate->add_option("--config", migrate_args.config_file,
                      "the stand's imucald configuration: its registry.stand and limits_file")
      ->check(CLI::ExistingFile);
  migrate->add_option("--stand", migrate_args.stand,
                      "the stand's name in the lab (registry.stand; default: the configuration's, else the host's name)");
  migrate->add_option("--limits", migrate_args.limits_file,
                      "the stand's limits file (default: the configuration's limits_file, else DATA_DIR/limits.json)");
  migrate->add_option("--operator", migrate_args.operator_name,
                      "who migrates, for the lab's audit trail (default: the login name)");
  migrate->add_flag("--dry-run", migrate_args.dry_run, "print what would be copied and write nothing");

  // bench record|read (storage): they run from CLI11's callbacks, inside CLI11_PARSE.
  auto* bench = app.add_subcommand("bench", "Benchmarks of the run storage: bench record, bench read");
  imucal::bench::add_storage_bench_commands(*bench);

  if (const int status = imucal::daemon::parse_command_line(app, argc, argv); status >= 0) return status;
  try {
    if (camp_run->parsed()) {
      if (camp_time_scale >= 0) camp_opts.time_scale = camp_time_scale;
      camp_opts.progress = !camp_json;
      if (camp_override_opt->count() > 0) camp_opts.override_overdue = camp_override;
      return cli::run_campaign(camp_file, camp_opts, camp_json);
    }
    if (sim->parsed()) return cli::run_simulate(sim_args);
    if (navc->parsed()) return cli::run_navigate(nav_args);
    if (cal->parsed()) return cli::run_calibrate(cal_args);
    if (ev->parsed()) return cli::run_evaluate(eval_db, eval_models, eval_out);
    if (cmp->parsed()) return cli::run_compare(cmp_model, cmp_truth, cmp_json);
    if (simdev->parsed()) return cli::run_sim_devices(simdev_args);
    if (passwd->parsed()) return cli::run_passwd();
    if (keygen->parsed()) return cli::run_keygen(keygen_out);
    if (verify->parsed()) return cli::run_verify(verify_file, verify_key, verify_fingerprint);
    if (audit_verify->parsed()) {
      if (audit_dir.empty() == audit_postgresql.empty()) {
        std::fprintf(stderr, "imucal audit verify: give DATA_DIR or --postgresql CONNINFO (one of them)\n");
        return 2;
      }
      return audit_dir.empty() ? cli::run_audit_verify_postgresql(audit_postgresql) : cli::run_audit_verify(audit_dir);
    }
    if (migrate->parsed()) return cli::run_registry_migrate(migrate_args);
    if (registry_init->parsed()) return cli::run_registry_init(init_to);
    if (planc->parsed()) {
      plan_opt.settings.navigation.attitude_noise_rad = plan_table_attitude_arcsec * units::kArcsecToRad;
      if (!plan_table.empty()) plan_opt.table = table::read_table_certificate_file(plan_table);
      if (plan_table_sigma_arcsec > 0) plan_opt.table = plan::uniform_table_certificate(plan_table_sigma_arcsec);
      if (planc->count("--gravity-sigma-mps2") > 0) {
        plan_opt.settings.direct.gravity_sigma_mps2 = plan_gravity_sigma_mps2;
        plan_opt.settings.navigation.gravity_sigma_mps2 = plan_gravity_sigma_mps2;
      }
      if (plan_optimize) {
        plan_search.predict = plan_opt;
        // Many programs are predicted: 20 Hz unless a rate is given.
        if (planc->count("--rate") == 0) plan_search.predict.rate_hz = 20.0;
        return cli::run_plan_optimize(plan_program, plan_imu, plan_search, plan_target, plan_program_out, plan_json);
      }
      return cli::run_plan(plan_program, plan_imu, plan_opt, plan_json);
    }
    if (exp->parsed()) return cli::run_export(exp_db, exp_dir);
    if (imp->parsed()) return cli::run_import(imp_dir, imp_db);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "\nimucal %s: error: %s\n", app.get_subcommands().front()->get_name().c_str(), e.what());
    return 1;
  }
  return 0;
}

