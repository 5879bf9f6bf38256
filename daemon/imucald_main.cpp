// imucald: the calibration bench service (docs/daemon.md). Flags override the configuration file;
// with neither it runs simulated devices, keeps its data in ./data and listens on 127.0.0.1:8080.
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "daemon/config/command_line.hpp"
#include "daemon/config/config.hpp"
#include "daemon/service.hpp"

using namespace imucal::daemon;

int main(int argc, char** argv) {
  CLI::App app{"imucald: runs calibration campaigns on the bench (table, chamber, IMU) and serves the API and UI", "imucald"};
  std::string config_file, listen, data_dir, devices, operator_token, log_level;
  app.add_option("--config", config_file, "configuration JSON (see examples/imucald.json)")->check(CLI::ExistingFile);
  app.add_option("--listen", listen, "HTTP address HOST:PORT (default 127.0.0.1:8080; port 0: any free port)");
  app.add_option("--data-dir", data_dir, "data directory: daemon database, run files, logs (default ./data)");
  app.add_option("--devices", devices,
                 "sim (in-process simulated bench) or sim-wire (simulated devices on loopback); a real bench is "
                 "named only in the configuration file (its \"devices\" object, see examples/imucald.json)")
      ->check(CLI::IsMember({"sim", "sim-wire"}));
  app.add_option("--operator-token", operator_token, "API token with the operator role (at least 16 characters)");
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}));
  if (const int status = imucal::daemon::parse_command_line(app, argc, argv); status >= 0) return status;

  DaemonConfig config;
  try {
    if (!config_file.empty()) config = load_config_file(config_file);
    if (!listen.empty()) parse_listen(listen, config.http.host, config.http.port);
    if (!data_dir.empty()) config.data_dir = data_dir;
    if (!devices.empty()) config.devices = devices;
    if (!log_level.empty()) config.log.level = log_level;
    if (!operator_token.empty()) {
      if (operator_token.size() < 16) throw ConfigError("--operator-token must have at least 16 characters");
      config.operator_token = operator_token;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "imucald: %s\n", e.what());
    return 2;
  }

  // SIGTERM and SIGINT are taken by this thread with sigwait(), before any other thread starts.
  const sigset_t signals = block_termination_signals();

  try {
    std::filesystem::create_directories(config.data_dir);
    setup_logging(config.log, config.data_dir);
    Service service(config);
    try {
      service.start(true);
    } catch (...) {
      // A token generated for a start that failed (e.g. the port in use) was never printed: take it
      // back, so that the next start generates one and prints it.
      if (!service.auth().generated_token().empty()) std::filesystem::remove(service.auth().token_file());
      throw;
    }
    spdlog::info("imucald {}: devices '{}', data in '{}', web UI from '{}'", IMUCAL_VERSION, config.devices,
                 config.data_dir, service.web_dir().empty() ? "(none)" : service.web_dir());
    // On stdout for scripts and tests (the actual port when 0 was asked for).
    std::printf("imucald: listening on http://%s:%u\n", config.http.host.c_str(), static_cast<unsigned>(service.port()));
    if (!service.auth().generated_token().empty()) {
      std::printf(
          "imucald: no operator credential is configured; generated a one-time operator token (kept in %s):\n"
          "  %s\n"
          "  use it as 'Authorization: Bearer <token>' or to sign in from the browser\n",
          service.auth().token_file().c_str(), service.auth().generated_token().c_str());
      spdlog::warn("generated an operator token, stored in {}", service.auth().token_file());
    }
    std::fflush(stdout);

    int signal_number = 0;
    sigwait(&signals, &signal_number);
    spdlog::info("{}: shutting down (parking the table, flushing the recorder, closing sessions)",
                 signal_number == SIGTERM ? "SIGTERM" : "SIGINT");
    service.stop();
    spdlog::info("imucald stopped");
    spdlog::shutdown();
    return 0;
  } catch (const std::exception& e) {
    spdlog::critical("{}", e.what());
    std::fprintf(stderr, "imucald: error: %s\n", e.what());
    return 1;
  }
}
