#include "drivers/imu_transport.hpp"

#include <cerrno>
#include <cstring>

#include <arpa/inet.h>
#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/serial_port.hpp>

namespace imucal::drivers {

namespace {

// A deep receive queue rides out scheduling hiccups of the polling thread without losing frames
// (best effort: the kernel clamps it to net.core.rmem_max).
constexpr int kReceiveQueueBytes = 4 << 20;

std::string errno_text(int e) { return std::strerror(e); }

// Kernel receive stamps: nanoseconds if the kernel offers them, else microseconds.
Result<void> enable_stamps(int fd, const std::string& who) {
  const int on = 1;
  if (::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) != 0 &&
      ::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMP, &on, sizeof on) != 0)
    return {DriverErrc::connect_failed, who + ": cannot enable receive time stamps: " + errno_text(errno)};
  (void)::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &kReceiveQueueBytes, sizeof kReceiveQueueBytes);
  return success();
}

constexpr ssize_t kNothingQueued = -2;

// One datagram with its kernel receive stamp (host_time_ns() when the socket gives none).
// Returns its size (0: the peer closed a connected socket), kNothingQueued, or -1 with `error`
// set when the link failed.
ssize_t receive_stamped(int fd, std::uint8_t* buf, std::size_t capacity, std::int64_t& rx_ns, sockaddr_storage* from,
                        const std::string& who, Result<void>& error) {
  for (;;) {
    alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(timeval)) + 64];
    iovec iov{buf, capacity};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control;
    msg.msg_controllen = sizeof control;
    if (from) {
      msg.msg_name = from;
      msg.msg_namelen = sizeof *from;
    }
    const ssize_t n = ::recvmsg(fd, &msg, MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) return kNothingQueued;
      if (errno == EINTR) continue;
      error = Result<void>(DriverErrc::connection_lost, who + ": receive failed: " + errno_text(errno));
      return -1;
    }
    rx_ns = 0;
    for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c; c = CMSG_NXTHDR(&msg, c)) {
      if (c->cmsg_level != SOL_SOCKET) continue;
      if (c->cmsg_type == SCM_TIMESTAMPNS) {
        timespec ts;
        std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
        rx_ns = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
      } else if (c->cmsg_type == SCM_TIMESTAMP) {
        timeval tv;
        std::memcpy(&tv, CMSG_DATA(c), sizeof tv);
        rx_ns = static_cast<std::int64_t>(tv.tv_sec) * 1'000'000'000 + tv.tv_usec * 1000;
      }
    }
    if (rx_ns == 0) rx_ns = host_time_ns();  // no kernel stamp: the best we have
    return n;
  }
}

// ------------------------------------------------------------------------------------------------

class SocketCanTransport final : public ImuTransport {
 public:
  SocketCanTransport(int fd, const link::ImuLink& link, can::Framing framing, std::string where)
      : fd_(fd), framing_(framing), where_(std::move(where)), sample_length_(link.messages[link.sample_message()].length) {
    // An identifier names its message; one shared by several (pages of a set) leaves the header
    // to tell them apart.
    const auto add = [](auto& list, std::uint32_t id, std::size_t message, auto make) {
      for (auto& e : list) {
        if (e.id != id) continue;
        e.message.reset();
        return;
      }
      list.push_back(make(id, message));
    };
    for (std::size_t i = 0; i < link.messages.size(); ++i) {
      const link::Message& m = link.messages[i];
      if (m.can_id) add(fd_ids_, *m.can_id, i, [](std::uint32_t id, std::size_t k) { return FdId{id, k}; });
      if (m.classic_base_id)
        add(assemblers_, *m.classic_base_id, i,
            [&](std::uint32_t id, std::size_t k) { return Stream{id, can::ClassicAssembler(id, m.length), k}; });
    }
  }
  ~SocketCanTransport() override { close(); }

  Result<void> open() override {
    if (fd_ < 0 || ::fcntl(fd_, F_GETFD) < 0) return {DriverErrc::connect_failed, where_ + ": no open socket"};
    return enable_stamps(fd_, where_);
  }
  int wait_handle() const noexcept override { return fd_; }
  std::string describe() const override { return where_; }
  std::optional<double> max_rate_hz() const override {
    if (framing_ == can::Framing::classic) return can::kClassicMaxRate_hz * 10.0 / static_cast<double>(can::classic_parts(sample_length_));
    return std::nullopt;
  }
  std::uint64_t malformed() const noexcept override {
    std::uint64_t n = unparsed_;
    for (const auto& a : assemblers_) n += a.assembler.incomplete();
    return n;
  }
  void reset() noexcept override {
    for (auto& a : assemblers_) a.assembler.reset();
  }

  Result<void> drain(std::vector<LinkChunk>& out) override {
    for (;;) {
      std::uint8_t buf[can::kCanFdMtu + 8];
      std::int64_t rx_ns = 0;
      Result<void> error;
      const ssize_t n = receive_stamped(fd_, buf, sizeof buf, rx_ns, nullptr, where_, error);
      if (n == kNothingQueued) return success();
      if (n < 0) return error;
      if (n == 0) return {DriverErrc::connection_lost, where_ + ": the link was closed by the other end"};
      const auto f = can::parse_wire(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(n)));
      if (!f) {
        ++unparsed_;
        continue;
      }
      if (f->fd) {
        for (const auto& [id, message] : fd_ids_) {
          if (f->can_id != id) continue;
          out.push_back({std::vector<std::uint8_t>(f->data.begin(), f->data.begin() + f->len), rx_ns, message});
          break;
        }
        continue;
      }
      for (auto& a : assemblers_) {
        if (!a.assembler.owns(f->can_id)) continue;
        if (auto bytes = a.assembler.feed(*f)) out.push_back({std::move(*bytes), rx_ns, a.message});
        break;
      }
      // Other identifiers belong to other nodes on the bus: not ours to count.
    }
  }

  Result<void> send(const link::Command& command) override {
    const auto wire = can::to_wire(can::classic_frame(command.can_id.value_or(0), command.bytes));
    const ssize_t n = ::send(fd_, wire.data(), wire.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n == static_cast<ssize_t>(wire.size())) return success();
    const int e = errno;
    if (n < 0 && (e == EPIPE || e == ECONNRESET || e == ENOTCONN))
      return {DriverErrc::connection_lost, where_ + ": link lost sending a command: " + errno_text(e)};
    return {DriverErrc::io_error, where_ + ": cannot send a command: " + (n < 0 ? errno_text(e) : "short write")};
  }

  void close() noexcept override {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  struct Stream {
    std::uint32_t id;
    can::ClassicAssembler assembler;
    std::optional<std::size_t> message;
  };
  struct FdId {
    std::uint32_t id;
    std::optional<std::size_t> message;
  };
  int fd_;
  can::Framing framing_;
  std::string where_;
  std::size_t sample_length_;
  std::vector<FdId> fd_ids_;
  std::vector<Stream> assemblers_;
  std::uint64_t unparsed_ = 0;
};

// ------------------------------------------------------------------------------------------------

class SerialTransport final : public ImuTransport {
 public:
  SerialTransport(std::string device, const link::ImuLink& link)
      : device_(std::move(device)), line_(link.serial), sample_length_(link.messages[link.sample_message()].length) {}
  ~SerialTransport() override { close(); }

  std::string describe() const override {
    return "serial " + device_ + " (" + std::to_string(line_.baud) + " Bd, " + std::to_string(line_.data_bits) +
           (line_.parity == link::Parity::none ? "N" : line_.parity == link::Parity::odd ? "O" : "E") +
           std::to_string(line_.stop_bits) + ")";
  }

  Result<void> open() override {
    using boost::asio::serial_port_base;
    close();
    boost::system::error_code ec;
    port_.open(device_, ec);
    if (ec) return {DriverErrc::connect_failed, "cannot open serial device '" + device_ + "': " + ec.message()};
    const auto parity = line_.parity == link::Parity::none  ? serial_port_base::parity::none
                        : line_.parity == link::Parity::odd ? serial_port_base::parity::odd
                                                            : serial_port_base::parity::even;
    const auto stop = line_.stop_bits == 2 ? serial_port_base::stop_bits::two : serial_port_base::stop_bits::one;
    const char* what = "baud rate";
    port_.set_option(serial_port_base::baud_rate(line_.baud), ec);
    if (!ec) {
      what = "character size";
      port_.set_option(serial_port_base::character_size(line_.data_bits), ec);
    }
    if (!ec) {
      what = "parity";
      port_.set_option(serial_port_base::parity(parity), ec);
    }
    if (!ec) {
      what = "stop bits";
      port_.set_option(serial_port_base::stop_bits(stop), ec);
    }
    if (!ec) {
      what = "flow control";
      port_.set_option(serial_port_base::flow_control(serial_port_base::flow_control::none), ec);
    }
    if (ec) {
      port_.close(ec);
      return {DriverErrc::connect_failed, describe() + ": cannot set the " + what + ": " + ec.message()};
    }
    // Reads are polled by the driver: the descriptor itself must never block.
    const int fd = port_.native_handle();
    if (::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK) != 0)
      return {DriverErrc::connect_failed, describe() + ": cannot make the line non-blocking: " + errno_text(errno)};
    fd_ = fd;
    return success();
  }
  int wait_handle() const noexcept override { return fd_; }
  std::optional<double> max_rate_hz() const override {
    // Each character is a start bit, the data bits, a parity bit if any and the stop bits.
    const unsigned bits = 1 + line_.data_bits + (line_.parity == link::Parity::none ? 0u : 1u) + line_.stop_bits;
    return static_cast<double>(line_.baud) / (static_cast<double>(bits) * static_cast<double>(sample_length_));
  }

  Result<void> drain(std::vector<LinkChunk>& out) override {
    if (fd_ < 0) return {DriverErrc::connection_lost, describe() + ": not open"};
    for (;;) {
      std::uint8_t buf[4096];
      const ssize_t n = ::read(fd_, buf, sizeof buf);
      if (n > 0) {
        // A tty gives no kernel receive stamp: the time of the read, late by however long the
        // bytes waited (the clock model's lower envelope takes the earliest).
        out.push_back({std::vector<std::uint8_t>(buf, buf + n), host_time_ns(), std::nullopt});
        continue;
      }
      if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return success();
      if (n < 0 && errno == EINTR) continue;
      // 0 or EIO: the far end hung up (an adapter unplugged, the pseudo-terminal's master closed).
      const std::string why = n == 0 ? "end of file" : errno_text(errno);
      return {DriverErrc::connection_lost, describe() + ": the line was closed (" + why + ")"};
    }
  }

  Result<void> send(const link::Command& command) override {
    if (fd_ < 0) return {DriverErrc::connection_lost, describe() + ": not open"};
    const ssize_t n = ::write(fd_, command.bytes.data(), command.bytes.size());
    if (n == static_cast<ssize_t>(command.bytes.size())) return success();
    return {DriverErrc::io_error, describe() + ": cannot send a command: " + (n < 0 ? errno_text(errno) : "short write")};
  }

  void close() noexcept override {
    boost::system::error_code ec;
    if (port_.is_open()) port_.close(ec);
    fd_ = -1;
  }

 private:
  int fd_ = -1;
  std::string device_;
  link::SerialLine line_;
  std::size_t sample_length_;
  boost::asio::io_context io_;
  boost::asio::serial_port port_{io_};
};

// ------------------------------------------------------------------------------------------------

Result<sockaddr_in> resolve_ipv4(const std::string& host, int port, const std::string& who) {
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* res = nullptr;
  const int rc = ::getaddrinfo(host.c_str(), nullptr, &hints, &res);
  if (rc != 0 || !res) return {DriverErrc::connect_failed, who + ": cannot resolve '" + host + "': " + ::gai_strerror(rc)};
  sockaddr_in a{};
  std::memcpy(&a, res->ai_addr, sizeof a);
  ::freeaddrinfo(res);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  return a;
}

class UdpTransport final : public ImuTransport {
 public:
  UdpTransport(std::string bind_host, int port, std::string peer_host, int peer_port)
      : bind_host_(std::move(bind_host)), port_(port), peer_host_(std::move(peer_host)), peer_port_(peer_port) {}
  ~UdpTransport() override { close(); }

  std::string describe() const override {
    return "UDP " + bind_host_ + ":" + std::to_string(port_) +
           (peer_host_.empty() ? std::string() : " from " + peer_host_ + ":" + std::to_string(peer_port_));
  }
  Result<void> open() override {
    close();
    const std::string who = "cannot open " + describe();
    auto local = resolve_ipv4(bind_host_, port_, who);
    if (!local) return local.error();
    if (!peer_host_.empty()) {
      auto peer = resolve_ipv4(peer_host_, peer_port_, who);
      if (!peer) return peer.error();
      peer_ = *peer;
    }
    fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0) return {DriverErrc::connect_failed, who + ": socket: " + errno_text(errno)};
    if (::bind(fd_, reinterpret_cast<const sockaddr*>(&*local), sizeof(sockaddr_in)) != 0) {
      const int e = errno;
      close();
      return {DriverErrc::connect_failed, who + ": bind: " + errno_text(e)};
    }
    return enable_stamps(fd_, describe());
  }
  int wait_handle() const noexcept override { return fd_; }
  std::optional<double> max_rate_hz() const override { return std::nullopt; }
  std::uint64_t malformed() const noexcept override { return foreign_; }

  Result<void> drain(std::vector<LinkChunk>& out) override {
    for (;;) {
      std::uint8_t buf[65536];
      std::int64_t rx_ns = 0;
      sockaddr_storage from{};
      Result<void> error;
      const ssize_t n = receive_stamped(fd_, buf, sizeof buf, rx_ns, &from, describe(), error);
      if (n == kNothingQueued) return success();
      if (n < 0) return error;
      if (peer_) {
        const auto* a = reinterpret_cast<const sockaddr_in*>(&from);
        if (a->sin_addr.s_addr != peer_->sin_addr.s_addr || a->sin_port != peer_->sin_port) {
          ++foreign_;  // not the configured IMU: never its data
          continue;
        }
      }
      out.push_back({std::vector<std::uint8_t>(buf, buf + n), rx_ns, std::nullopt});
    }
  }

  Result<void> send(const link::Command& command) override {
    if (!peer_) return {DriverErrc::invalid_argument, describe() + ": the description has commands: the IMU's address (udp_peer) is needed"};
    const ssize_t n = ::sendto(fd_, command.bytes.data(), command.bytes.size(), MSG_DONTWAIT,
                               reinterpret_cast<const sockaddr*>(&*peer_), sizeof(sockaddr_in));
    if (n == static_cast<ssize_t>(command.bytes.size())) return success();
    return {DriverErrc::io_error, describe() + ": cannot send a command: " + (n < 0 ? errno_text(errno) : "short write")};
  }

  void close() noexcept override {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  std::string bind_host_;
  int port_;
  std::string peer_host_;
  int peer_port_;
  std::optional<sockaddr_in> peer_;
  int fd_ = -1;
  std::uint64_t foreign_ = 0;
};

}  // namespace

Result<int> open_socketcan(const std::string& interface, bool fd_frames) {
  const std::string who = "cannot open CAN interface '" + interface + "': ";
  if (interface.empty() || interface.size() >= IFNAMSIZ)
    return {DriverErrc::invalid_argument, who + "an interface name has 1 to " + std::to_string(IFNAMSIZ - 1) + " characters"};
  const int s = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
  if (s < 0) {
    const int e = errno;
    std::string why = std::string("socket(AF_CAN, SOCK_RAW, CAN_RAW) failed: ") + std::strerror(e);
    if (e == EAFNOSUPPORT || e == EPROTONOSUPPORT)
      why += " (this kernel has no SocketCAN support; load the can and can_raw modules or use a machine with a CAN interface)";
    return {DriverErrc::connect_failed, who + why};
  }
  const unsigned index = ::if_nametoindex(interface.c_str());
  if (index == 0) {
    const int e = errno;
    ::close(s);
    return {DriverErrc::connect_failed, who + "no such network interface (" + std::strerror(e) + ")"};
  }
  if (fd_frames) {
    const int on = 1;
    if (::setsockopt(s, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) != 0) {
      const int e = errno;
      ::close(s);
      return {DriverErrc::connect_failed, who + "CAN FD frames not supported: " + std::strerror(e)};
    }
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = static_cast<int>(index);
  if (::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    const int e = errno;
    ::close(s);
    return {DriverErrc::connect_failed, who + "bind failed: " + std::strerror(e)};
  }
  return s;
}

std::unique_ptr<ImuTransport> socketcan_transport(int socket_fd, const link::ImuLink& link, can::Framing framing,
                                                  std::string where) {
  return std::make_unique<SocketCanTransport>(socket_fd, link, framing, std::move(where));
}

std::unique_ptr<ImuTransport> serial_transport(std::string device, const link::ImuLink& link) {
  return std::make_unique<SerialTransport>(std::move(device), link);
}

std::unique_ptr<ImuTransport> udp_transport(std::string bind_host, int port, std::string peer_host, int peer_port) {
  return std::make_unique<UdpTransport>(std::move(bind_host), port, std::move(peer_host), peer_port);
}

}  // namespace imucal::drivers
