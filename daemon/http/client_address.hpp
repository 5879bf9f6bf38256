// Who a request comes from, for what is counted per client (sign-in throttling): the TCP peer,
// or, when the peer is a reverse proxy the configuration trusts (http.trusted_proxies), the
// address that proxy says it served. Behind nginx every request comes from 127.0.0.1; without
// this, one guesser would lock every operator out as if the lab were one client.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace imucal::daemon {

// `peer`: the TCP peer's address; `forwarded_for`: the X-Forwarded-For header as received (empty
// when absent); `trusted`: the proxies' addresses. When the peer is trusted, the header's entries
// are read from the right (each proxy appends the address it was reached from) past every trusted
// one: the first untrusted entry is the client (what is left of it, the client itself may have
// written). A header that is missing, or whose entry there is not an IP address, leaves the peer.
std::string client_address(const std::string& peer, std::string_view forwarded_for, const std::vector<std::string>& trusted);

}  // namespace imucal::daemon
