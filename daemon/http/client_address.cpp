#include "daemon/http/client_address.hpp"

#include <algorithm>

#include <boost/asio/ip/address.hpp>

namespace imucal::daemon {

namespace {

// The address as Boost.Asio writes it (so that "::ffff:10.0.0.1" spellings and the trusted list
// compare alike), or empty when it is not one.
std::string canonical(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.remove_suffix(1);
  boost::system::error_code ec;
  const auto a = boost::asio::ip::make_address(std::string(text), ec);
  return ec ? std::string() : a.to_string();
}

}  // namespace

std::string client_address(const std::string& peer, std::string_view forwarded_for, const std::vector<std::string>& trusted) {
  std::vector<std::string> trusted_canonical;
  for (const auto& t : trusted) trusted_canonical.push_back(canonical(t));
  auto is_trusted = [&](const std::string& a) {
    return !a.empty() && std::find(trusted_canonical.begin(), trusted_canonical.end(), a) != trusted_canonical.end();
  };
  if (!is_trusted(canonical(peer)) || forwarded_for.empty()) return peer;
  std::string_view rest = forwarded_for;
  while (!rest.empty()) {
    const auto comma = rest.rfind(',');
    const std::string_view entry = comma == std::string_view::npos ? rest : rest.substr(comma + 1);
    rest = comma == std::string_view::npos ? std::string_view() : rest.substr(0, comma);
    const std::string address = canonical(entry);
    if (address.empty()) return peer;  // not an address: the proxy's word cannot be read
    if (!is_trusted(address)) return address;
  }
  return peer;  // every entry a trusted proxy: the request began at one of them
}

}  // namespace imucal::daemon
