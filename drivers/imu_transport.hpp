// The thin transports under the generic IMU driver (link_imu.hpp): SocketCAN (or a Unix
// SOCK_SEQPACKET socket carrying the same frame images), a serial line opened with Boost.Asio's
// serial_port and the description's line settings, and UDP. They only move bytes and stamp their
// arrival (kernel receive stamps where the socket has them); what the bytes mean is the codec's.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "drivers/can_protocol.hpp"
#include "drivers/imu_link.hpp"
#include "drivers/interfaces.hpp"

namespace imucal::drivers {

// What one read gives: a whole frame (CAN, UDP) or a piece of the byte stream (serial).
struct LinkChunk {
  std::vector<std::uint8_t> bytes;
  std::int64_t rx_ns = 0;                // host time base
  std::optional<std::size_t> message;    // the message its CAN identifier names
};

class ImuTransport {
 public:
  virtual ~ImuTransport() = default;
  // Opens the link (or readies the descriptor handed over): receive stamps, queue sizes.
  virtual Result<void> open() = 0;
  virtual int wait_handle() const noexcept = 0;  // a descriptor to poll() for input
  // Everything queued, without waiting. connection_lost when the other end closed the link.
  virtual Result<void> drain(std::vector<LinkChunk>& out) = 0;
  virtual Result<void> send(const link::Command& command) = 0;
  virtual void close() noexcept = 0;
  virtual std::string describe() const = 0;
  // The highest sample rate the link carries for this description (a classic CAN bus, a baud
  // rate); empty when the transport sets no limit of its own.
  virtual std::optional<double> max_rate_hz() const = 0;
  // Link-level frames that could not be used (a broken classic-CAN set, an unparseable frame).
  virtual std::uint64_t malformed() const noexcept { return 0; }
  virtual void reset() noexcept {}  // forget partial messages: a new run starts
};

// Opens a CAN_RAW socket bound to `interface` (CAN FD frames enabled when fd_frames). On failure
// the message names the interface and the reason (e.g. a kernel without AF_CAN support).
Result<int> open_socketcan(const std::string& interface, bool fd_frames);

// SocketCAN: takes ownership of `socket_fd` (a CAN_RAW socket or one end of a SOCK_SEQPACKET
// pair); each message of `link` travels in a CAN FD frame with its can_id, or under `classic` in
// classic frames from its classic_base_id. `where` names the link in messages.
std::unique_ptr<ImuTransport> socketcan_transport(int socket_fd, const link::ImuLink& link, can::Framing framing,
                                                  std::string where);
// A serial device (RS-422 adapter, or a pseudo-terminal in tests) with the description's baud
// rate, parity, data and stop bits, no flow control.
std::unique_ptr<ImuTransport> serial_transport(std::string device, const link::ImuLink& link);
// UDP datagrams to `bind_host:port`. With a `peer_host:peer_port`, commands go there and only
// its datagrams are taken.
std::unique_ptr<ImuTransport> udp_transport(std::string bind_host, int port, std::string peer_host, int peer_port);

}  // namespace imucal::drivers
