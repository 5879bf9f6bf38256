#include "sim/sim_devices.hpp"

#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <termios.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <thread>

#include <nlohmann/json.hpp>

#include "drivers/imu_link.hpp"
#include "drivers/register_map.hpp"

namespace imucal::sim {

// The simulated devices speak the drivers' types and protocols.
using namespace imucal::drivers;

namespace {

SimChamberConfig chamber_config(const SimDevicesConfig& c) {
  SimChamberConfig s;
  s.map = load_register_map(c.chamber_map);
  s.initial_C = c.chamber_start_C;
  s.ambient_C = c.chamber_start_C;
  s.time_constant_s = c.chamber_tau_s;
  s.time_scale = c.time_scale;
  s.port = c.chamber_port;
  return s;
}

SimTableConfig table_config(const SimDevicesConfig& c) {
  SimTableConfig s;
  s.port = c.table_port;
  s.dialect = dialect::load_dialect(c.table_dialect);
  return s;
}

// A listening Unix SOCK_SEQPACKET socket on `path`. A socket file left behind by an earlier run is
// replaced; any other file at the path is refused rather than deleted.
int listen_unix(const std::string& path) {
  const std::string who = "simulated IMU: cannot listen on '" + path + "': ";
  sockaddr_un addr{};
  if (path.empty() || path.size() >= sizeof addr.sun_path)
    throw std::runtime_error(who + "a socket path has 1 to " + std::to_string(sizeof addr.sun_path - 1) + " characters");
  struct stat st{};
  if (::lstat(path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode)) throw std::runtime_error(who + "the path exists and is not a socket");
    ::unlink(path.c_str());
  }
  const int fd = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) throw std::runtime_error(who + "socket(AF_UNIX, SOCK_SEQPACKET): " + std::strerror(errno));
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path.data(), path.size());
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0 || ::listen(fd, 4) != 0) {
    const int e = errno;
    ::close(fd);
    throw std::runtime_error(who + std::strerror(e));
  }
  return fd;
}

}  // namespace

struct SimDevices::Impl {
  SimDevicesConfig cfg;
  SimWorld world;
  SimTable table;
  SimChamber chamber;

  mutable std::mutex imu_mutex;
  std::unique_ptr<SimImu> imu;
  std::atomic<std::uint64_t> links{0};

  int listen_fd = -1;
  std::atomic<bool> stop{false};
  std::thread acceptor;
  // A serial IMU: the pseudo-terminal's slave side, held open so that the line stays up between
  // the daemon's runs (each opens the device by its path), as a cable stays plugged in.
  int pty_slave_fd = -1;
  std::string pty_path;

  explicit Impl(SimDevicesConfig c)
      : cfg(std::move(c)), world(cfg.servo, drivers::host_time_ns(), cfg.time_scale), table(world, table_config(cfg)), chamber(chamber_config(cfg)) {
    cfg.imu.link = link::load_imu_link(cfg.imu_link);
    if (cfg.imu.serial.empty()) cfg.imu.serial = cfg.imu_serial;  // what it reports, if its link can
    chamber.set_coil(kImuPowerCoil, true);
  }

  void attach(int fd) {
    // The new IMU starts before the old one is dropped: dropping joins its thread, which must not
    // happen under the lock that fault injection takes.
    auto fresh = std::make_unique<SimImu>(world, fd, cfg.imu);
    std::unique_ptr<SimImu> old;
    {
      std::lock_guard lock(imu_mutex);
      old = std::move(imu);
      imu = std::move(fresh);
    }
    ++links;
  }

  void accept_loop() {
    while (!stop) {
      pollfd p{listen_fd, POLLIN, 0};
      // A bounded wait, so that the destructor's stop is seen promptly.
      if (::poll(&p, 1, 100) <= 0) continue;
      const int fd = ::accept4(listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) continue;
      try {
        attach(fd);
      } catch (const std::exception&) {
        // The IMU could not be built (no thread): it never took the descriptor. Closing the link
        // tells the daemon at once instead of through its stall timeout.
        ::close(fd);
      }
    }
  }
};

SimDevices::SimDevices(SimDevicesConfig config) : impl_(std::make_unique<Impl>(std::move(config))) {
  const link::Transport transport = impl_->cfg.imu.link.transport;
  if (transport == link::Transport::udp)
    throw std::runtime_error("simulated IMU: link '" + impl_->cfg.imu.link.name + "' is UDP; the bench serves CAN and serial IMUs");
  if (transport == link::Transport::serial) {
    // Raw from the start: a cooked line discipline would echo, translate CR and buffer lines.
    termios raw{};
    ::cfmakeraw(&raw);
    int master = -1;
    char name[128] = {};
    if (::openpty(&master, &impl_->pty_slave_fd, name, &raw, nullptr) != 0)
      throw std::runtime_error(std::string("simulated IMU: cannot open a pseudo-terminal: ") + std::strerror(errno));
    impl_->pty_path = name;
    ::fcntl(master, F_SETFD, FD_CLOEXEC);
    ::fcntl(impl_->pty_slave_fd, F_SETFD, FD_CLOEXEC);
    impl_->attach(master);
  } else if (!impl_->cfg.imu_socket_path.empty()) {
    impl_->listen_fd = listen_unix(impl_->cfg.imu_socket_path);
    impl_->acceptor = std::thread([this] { impl_->accept_loop(); });
  }
}

SimDevices::~SimDevices() {
  impl_->stop = true;
  if (impl_->acceptor.joinable()) impl_->acceptor.join();
  if (impl_->listen_fd >= 0) {
    ::close(impl_->listen_fd);
    ::unlink(impl_->cfg.imu_socket_path.c_str());
  }
  {
    std::lock_guard lock(impl_->imu_mutex);
    impl_->imu.reset();
  }
  if (impl_->pty_slave_fd >= 0) ::close(impl_->pty_slave_fd);
}

const std::string& SimDevices::imu_serial_device() const noexcept { return impl_->pty_path; }

const SimDevicesConfig& SimDevices::config() const noexcept { return impl_->cfg; }
int SimDevices::table_port() const noexcept { return impl_->table.port(); }
int SimDevices::chamber_port() const noexcept { return impl_->chamber.port(); }
double SimDevices::gyro_lsb_rad() const noexcept { return SimImu::gyro_lsb_rad_at(impl_->cfg.imu.rate_hz); }
double SimDevices::accel_lsb_mps() const noexcept { return SimImu::accel_lsb_mps_at(impl_->cfg.imu.rate_hz); }
void SimDevices::attach_imu(int socket_fd) { impl_->attach(socket_fd); }
std::uint64_t SimDevices::imu_links() const noexcept { return impl_->links; }

bool SimDevices::with_imu(const std::function<void(SimImu&)>& f) {
  std::lock_guard lock(impl_->imu_mutex);
  if (!impl_->imu) return false;
  f(*impl_->imu);
  return true;
}

SimWorld& SimDevices::world() noexcept { return impl_->world; }
SimTable& SimDevices::table() noexcept { return impl_->table; }
SimChamber& SimDevices::chamber() noexcept { return impl_->chamber; }

std::string SimDevices::devices_config_json() const {
  using nlohmann::json;
  const SimDevicesConfig& c = impl_->cfg;
  json imu = {{"link", c.imu_link}, {"rate_hz", c.imu.rate_hz}, {"serial", c.imu_serial}};
  if (c.imu.link.transport == link::Transport::serial) {
    imu["serial_device"] = impl_->pty_path;
  } else {
    imu["socket"] = c.imu_socket_path;
    imu["framing"] = c.imu.framing == can::Framing::fd ? "fd" : "classic";
  }
  if (c.imu.link.gyro_lsb_per_unit()) imu["gyro_lsb_rad"] = gyro_lsb_rad();
  if (c.imu.link.accel_lsb_per_unit()) imu["accel_lsb_mps"] = accel_lsb_mps();
  const json devices = {
      {"table", {{"host", "127.0.0.1"}, {"port", table_port()}, {"dialect", c.table_dialect}}},
      {"chamber", {{"transport", "tcp"}, {"host", "127.0.0.1"}, {"port", chamber_port()}, {"map", c.chamber_map}}},
      {"imu", imu},
      {"power_relay", {{"host", "127.0.0.1"}, {"port", chamber_port()}, {"coil", kImuPowerCoil}}}};
  return devices.dump(2);
}

}  // namespace imucal::sim
