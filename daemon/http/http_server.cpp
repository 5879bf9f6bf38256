#include "daemon/http/http_server.hpp"
#include "daemon/http/client_address.hpp"

#include <atomic>
#include <chrono>
#include <deque>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include <boost/asio/dispatch.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <spdlog/spdlog.h>

#include "core/expect_value.hpp"
#include "core/json_reader.hpp"

namespace imucal::daemon {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace net = boost::asio;
using tcp = net::ip::tcp;
using nlohmann::json;

namespace {
constexpr std::size_t kHeaderLimitBytes = 16 * 1024;
constexpr std::size_t kWsMessageLimitBytes = 4096;  // clients send nothing of interest
}  // namespace

class LiveSession;
class HttpSession;
class ClientSlot;

struct HttpServer::Impl {
  Impl(const HttpConfig& c, Api& a, Sequencer& s, const StaticFiles& f)
      : config(c), api(a), sequencer(s), files(f), acceptor(ioc), telemetry_timer(ioc) {}

  void accept();
  void tick_telemetry();
  void send_to_all(std::shared_ptr<const std::string> message);
  void register_live(const std::shared_ptr<LiveSession>& s);
  void register_http(const std::shared_ptr<HttpSession>& s);
  void close_ended_sessions();
  // A slot for one more connection from `client`, or nothing when it has max_connections_per_client.
  std::shared_ptr<ClientSlot> take_slot(const std::string& client);

  // First, so that they outlive the io_context: a session its destruction drops gives back its slot.
  std::mutex slots_mutex;
  std::map<std::string, std::int64_t> connections_by_client;  // open connections per address
  HttpConfig config;
  Api& api;
  Sequencer& sequencer;
  const StaticFiles& files;
  net::io_context ioc;
  tcp::acceptor acceptor;
  net::steady_timer telemetry_timer;
  std::vector<std::thread> threads;
  std::uint16_t port = 0;

  std::mutex sessions_mutex;
  std::vector<std::weak_ptr<LiveSession>> live;
  std::vector<std::weak_ptr<HttpSession>> http_sessions;
  std::atomic<std::uint64_t> seq{0};
  std::atomic<bool> stopping{false};
  std::uint64_t ticks = 0;  // telemetry ticks (timer handler only)
};

// One open connection of a client, counted while it lives (the HTTP session holds it, then the
// WebSocket it becomes).
class ClientSlot {
 public:
  ClientSlot(HttpServer::Impl& server, std::string client) : server_(server), client_(std::move(client)) {}
  ~ClientSlot() {
    std::lock_guard lock(server_.slots_mutex);
    if (const auto it = server_.connections_by_client.find(client_);
        it != server_.connections_by_client.end() && --it->second <= 0)
      server_.connections_by_client.erase(it);
  }
  ClientSlot(const ClientSlot&) = delete;
  ClientSlot& operator=(const ClientSlot&) = delete;
  const std::string& client() const { return client_; }

 private:
  HttpServer::Impl& server_;
  std::string client_;
};

std::shared_ptr<ClientSlot> HttpServer::Impl::take_slot(const std::string& client) {
  std::lock_guard lock(slots_mutex);
  std::int64_t& n = connections_by_client[client];
  if (n >= config.max_connections_per_client) {
    if (n == 0) connections_by_client.erase(client);
    return nullptr;
  }
  ++n;
  return std::make_shared<ClientSlot>(*this, client);
}

// Close code of a live socket whose session has ended (4000-4999: for applications).
constexpr std::uint16_t kCloseSessionEnded = 4001;

// ------------------------------------------------------------------------------------------------
// WebSocket /api/live

class LiveSession : public std::enable_shared_from_this<LiveSession> {
 public:
  LiveSession(tcp::socket&& socket, HttpServer::Impl& server, std::shared_ptr<ClientSlot> slot)
      : ws_(std::move(socket)), server_(server), slot_(std::move(slot)) {}

  void run(http::request<http::string_body> request, const Principal& who) {
    role_ = to_string(who.role);
    session_id_ = who.session_id;
    ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
    ws_.set_option(websocket::stream_base::decorator(
        [](websocket::response_type& res) { res.set(http::field::server, "imucald"); }));
    ws_.read_message_max(kWsMessageLimitBytes);
    beast::get_lowest_layer(ws_).expires_never();  // the WebSocket's own timeouts apply
    request_ = std::move(request);
    ws_.async_accept(request_, beast::bind_front_handler(&LiveSession::on_accept, shared_from_this()));
  }

  // From any thread: queue a message, dropping the oldest when the client is too slow.
  void enqueue(std::shared_ptr<const std::string> message) {
    net::post(ws_.get_executor(), [self = shared_from_this(), message = std::move(message)]() mutable {
      if (self->closed_) return;
      if (self->queue_.size() >= static_cast<std::size_t>(self->server_.config.live_queue)) {
        // Drop the oldest message, but never the one being written (the front while writing).
        if (!self->writing_) {
          self->queue_.pop_front();
          ++self->dropped_;
        } else if (self->queue_.size() >= 2) {
          self->queue_.erase(std::next(self->queue_.begin()));
          ++self->dropped_;
        }
      }
      self->queue_.push_back(std::move(message));
      if (!self->writing_) self->write_next();
    });
  }

  void close(websocket::close_reason reason = websocket::close_code::going_away) {
    net::post(ws_.get_executor(), [self = shared_from_this(), reason] {
      if (self->closed_) return;
      self->closed_ = true;
      self->queue_.clear();
      self->ws_.async_close(reason, [self](beast::error_code) {});
    });
  }

  // The browser session that opened this socket (empty when a token did).
  const std::string& session_id() const { return session_id_; }

 private:
  void on_accept(beast::error_code ec) {
    if (ec) return;
    server_.register_live(shared_from_this());
    const json hello = {{"type", "hello"}, {"role", role_}, {"telemetry_hz", server_.config.live_rate_hz}};
    queue_.push_back(std::make_shared<const std::string>(json_text(hello)));
    write_next();
    do_read();
  }

  void do_read() {
    ws_.async_read(read_buffer_, beast::bind_front_handler(&LiveSession::on_read, shared_from_this()));
  }

  void on_read(beast::error_code ec, std::size_t) {
    if (ec) {
      closed_ = true;  // closed by the client, or a protocol error: stop writing too
      return;
    }
    read_buffer_.consume(read_buffer_.size());  // anything a client sends is ignored
    do_read();
  }

  void write_next() {
    if (queue_.empty() || closed_) {
      writing_ = false;
      return;
    }
    writing_ = true;
    if (dropped_ > 0 && queue_.front()->size() > 1 && queue_.front()->front() == '{') {
      // Tell this client how many messages it missed, in the next message it gets.
      auto with_count = std::make_shared<const std::string>("{\"dropped\":" + std::to_string(dropped_) + "," +
                                                            queue_.front()->substr(1));
      queue_.front() = std::move(with_count);
      dropped_ = 0;
    }
    ws_.text(true);
    ws_.async_write(net::buffer(*queue_.front()),
                    beast::bind_front_handler(&LiveSession::on_write, shared_from_this()));
  }

  void on_write(beast::error_code ec, std::size_t) {
    if (ec) {
      closed_ = true;
      queue_.clear();
      writing_ = false;
      return;
    }
    if (!queue_.empty()) queue_.pop_front();
    write_next();
  }

  websocket::stream<beast::tcp_stream> ws_;
  HttpServer::Impl& server_;
  http::request<http::string_body> request_;
  beast::flat_buffer read_buffer_;
  std::deque<std::shared_ptr<const std::string>> queue_;
  bool writing_ = false, closed_ = false;
  std::uint64_t dropped_ = 0;
  std::string role_;
  std::string session_id_;
  std::shared_ptr<ClientSlot> slot_;  // counted against its client's connections while open
};

// ------------------------------------------------------------------------------------------------
// Plain HTTP

class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket&& socket, HttpServer::Impl& server, std::shared_ptr<ClientSlot> slot)
      : stream_(std::move(socket)), server_(server), slot_(std::move(slot)) {}

  void run() {
    server_.register_http(shared_from_this());
    net::dispatch(stream_.get_executor(), beast::bind_front_handler(&HttpSession::do_read, shared_from_this()));
  }

  void close() {
    net::post(stream_.get_executor(), [self = shared_from_this()] {
      beast::error_code ignored;
      self->stream_.socket().shutdown(tcp::socket::shutdown_both, ignored);
      self->stream_.close();
    });
  }

 private:
  std::chrono::steady_clock::duration timeout() const {
    return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(server_.config.request_timeout_s));
  }

  void do_read() {
    parser_.emplace();
    parser_->body_limit(static_cast<std::uint64_t>(server_.config.body_limit_bytes));
    parser_->header_limit(kHeaderLimitBytes);
    stream_.expires_after(timeout());
    http::async_read(stream_, buffer_, *parser_, beast::bind_front_handler(&HttpSession::on_read, shared_from_this()));
  }

  void on_read(beast::error_code ec, std::size_t) {
    if (ec == http::error::end_of_stream) {
      beast::error_code ignored;
      stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
      return;
    }
    if (ec == http::error::body_limit) {
      send(json_response(http::status::payload_too_large, 11, false,
                         "request body larger than " + std::to_string(server_.config.body_limit_bytes) + " bytes"));
      return;
    }
    if (ec == http::error::header_limit) {
      send(json_response(http::status::request_header_fields_too_large, 11, false, "request headers too large"));
      return;
    }
    if (ec) return;  // timeout, reset, malformed request: drop the connection
    // The read that ends here was started on the parser do_read emplaced.
    http::request<http::string_body> req = expect_value(parser_, "the parser of the read that ended").release();

    if (websocket::is_upgrade(req)) {
      std::string path(req.target().substr(0, req.target().find('?')));
      if (path != "/api/live") {
        send(json_response(http::status::not_found, req.version(), false, "no WebSocket at " + path));
        return;
      }
      ApiRequest ar = to_api_request(req);
      const auto who = server_.api.authenticate(ar, true);
      // A page of another site may open a WebSocket with this site's cookie (browsers do not
      // apply CORS to it): a socket the cookie signs in must come from imucald's own pages.
      if (who && who->via == "session" && !ar.origin.empty() && !same_origin(ar.origin, ar.host)) {
        send(json_response(http::status::forbidden, req.version(), false,
                           "cross-origin WebSocket refused: Origin '" + ar.origin + "' is not this service ('" + ar.host + "')"));
        return;
      }
      if (!who || server_.stopping) {
        send(json_response(who ? http::status::service_unavailable : http::status::unauthorized, req.version(), false,
                           who ? "the daemon is shutting down" : "authentication required"));
        return;
      }
      stream_.expires_never();  // the WebSocket has its own timeouts
      std::make_shared<LiveSession>(stream_.release_socket(), server_, slot_)->run(std::move(req), *who);
      return;
    }
    respond(req);
  }

  ApiRequest to_api_request(const http::request<http::string_body>& req) const {
    ApiRequest ar;
    ar.method = std::string(req.method_string());
    ar.target = std::string(req.target());
    ar.authorization = std::string(req[http::field::authorization]);
    ar.cookie = std::string(req[http::field::cookie]);
    ar.content_type = std::string(req[http::field::content_type]);
    ar.origin = std::string(req[http::field::origin]);
    ar.host = std::string(req[http::field::host]);
    ar.client = slot_ ? client_address(slot_->client(), req["X-Forwarded-For"], server_.config.trusted_proxies)
                      : std::string();
    ar.body = req.body();
    return ar;
  }

  static http::response<http::string_body> json_response(http::status status, unsigned version, bool keep_alive,
                                                          const std::string& message) {
    http::response<http::string_body> res{status, version};
    res.set(http::field::server, "imucald");
    res.set(http::field::content_type, "application/json");
    res.set(http::field::cache_control, "no-store");
    res.body() = json_text({{"error", message}});
    res.keep_alive(keep_alive);
    res.prepare_payload();
    return res;
  }

  HttpReply reply_for(const http::request<http::string_body>& req) {
    const std::string target(req.target());
    HttpReply reply;
    if (target == "/api" || target.rfind("/api/", 0) == 0 || target.rfind("/api?", 0) == 0) {
      reply = server_.api.handle(to_api_request(req));
    } else if (req.method() == http::verb::get || req.method() == http::verb::head) {
      // HEAD reads the file too, so that its Content-Length is the GET's.
      reply = server_.files.get(std::string_view(target).substr(0, target.find('?')),
                                std::string(req[http::field::if_none_match]), false);
    } else {
      reply.status = 405;
      reply.body = json_text({{"error", std::string(req.method_string()) + " is not allowed on " + target}});
      reply.headers.emplace_back("Allow", "GET, HEAD");
    }
    return reply;
  }

  template <class Body>
  void set_headers(http::response<Body>& res, const http::request<http::string_body>& req, const HttpReply& reply) {
    res.set(http::field::server, "imucald");
    if (reply.status != 304) res.set(http::field::content_type, reply.content_type);
    for (const auto& [name, value] : reply.headers) res.insert(name, value);
    res.keep_alive(req.keep_alive() && !server_.stopping);
  }

  // Answers a request: a string body, or a file from the disk (downloads).
  void respond(const http::request<http::string_body>& req) {
    HttpReply reply = reply_for(req);
    if (reply.file.empty()) {
      send(to_response(req, std::move(reply)));
      return;
    }
    http::file_body::value_type file;
    beast::error_code ec;
    file.open(reply.file.c_str(), beast::file_mode::scan, ec);
    if (ec) {
      spdlog::error("http: cannot open {}: {}", reply.file, ec.message());
      send(json_response(http::status::internal_server_error, req.version(), req.keep_alive(),
                         "internal error: cannot open the file to send"));
      return;
    }
    if (req.method() == http::verb::head) {
      reply.body.clear();
      http::response<http::string_body> res = to_response(req, std::move(reply));
      res.content_length(file.size());
      send(std::move(res));
      return;
    }
    http::response<http::file_body> res{static_cast<http::status>(reply.status), req.version()};
    set_headers(res, req, reply);
    res.body() = std::move(file);
    res.prepare_payload();
    send(std::move(res), std::chrono::hours(1));  // a large bundle to a slow client
  }

  http::response<http::string_body> to_response(const http::request<http::string_body>& req, HttpReply reply) {
    http::response<http::string_body> res{static_cast<http::status>(reply.status), req.version()};
    set_headers(res, req, reply);
    if (req.method() == http::verb::head) {
      res.content_length(reply.body.size());  // what a GET would send; no body follows
    } else {
      res.body() = std::move(reply.body);
      res.prepare_payload();
    }
    return res;
  }

  template <class Body>
  void send(http::response<Body> res, std::chrono::steady_clock::duration write_timeout = {}) {
    auto shared = std::make_shared<http::response<Body>>(std::move(res));
    const bool close = !shared->keep_alive();
    stream_.expires_after(std::max(timeout(), write_timeout));
    http::async_write(stream_, *shared, [self = shared_from_this(), shared, close](beast::error_code ec, std::size_t) {
      if (ec) return;
      if (close) {
        beast::error_code ignored;
        self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
        return;
      }
      self->do_read();
    });
  }

  beast::tcp_stream stream_;
  HttpServer::Impl& server_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  std::shared_ptr<ClientSlot> slot_;  // counted against its client's connections while open
};

// ------------------------------------------------------------------------------------------------

void HttpServer::Impl::register_live(const std::shared_ptr<LiveSession>& s) {
  std::lock_guard lock(sessions_mutex);
  std::erase_if(live, [](const auto& w) { return w.expired(); });
  live.push_back(s);
}

void HttpServer::Impl::register_http(const std::shared_ptr<HttpSession>& s) {
  std::lock_guard lock(sessions_mutex);
  std::erase_if(http_sessions, [](const auto& w) { return w.expired(); });
  http_sessions.push_back(s);
}

void HttpServer::Impl::close_ended_sessions() {
  std::vector<std::shared_ptr<LiveSession>> ended;
  {
    std::lock_guard lock(sessions_mutex);
    for (auto& w : live)
      if (auto s = w.lock(); s && !s->session_id().empty()) ended.push_back(std::move(s));
  }
  for (auto& s : ended) {
    if (api.session_alive(s->session_id())) continue;
    s->close(websocket::close_reason(static_cast<websocket::close_code>(kCloseSessionEnded),
                                     "session ended; sign in again"));
    std::lock_guard lock(sessions_mutex);
    std::erase_if(live, [&](const auto& w) { return w.lock() == s; });
  }
}

void HttpServer::Impl::accept() {
  acceptor.async_accept(net::make_strand(ioc), [this](beast::error_code ec, tcp::socket socket) {
    if (ec) {
      if (ec == net::error::operation_aborted || stopping) return;
      spdlog::warn("http: accept: {}", ec.message());
    } else {
      beast::error_code peer_ec;
      const auto peer = socket.remote_endpoint(peer_ec);
      const std::string client = peer_ec ? std::string("?") : peer.address().to_string();
      if (auto slot = take_slot(client)) {
        std::make_shared<HttpSession>(std::move(socket), *this, std::move(slot))->run();
      } else {
        // Over its bound: told so in a few bytes (which fit any socket buffer), then closed.
        static const std::string refusal = [] {
          const std::string body = json_text({{"error", "too many connections from this address; close some and retry"}});
          return "HTTP/1.1 429 Too Many Requests\r\nContent-Type: application/json\r\nConnection: close\r\n"
                 "Content-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body;
        }();
        beast::error_code ignored;
        socket.non_blocking(true, ignored);
        socket.write_some(net::buffer(refusal), ignored);
        socket.shutdown(tcp::socket::shutdown_both, ignored);
        socket.close(ignored);
      }
    }
    if (!stopping) accept();
  });
}

void HttpServer::Impl::send_to_all(std::shared_ptr<const std::string> message) {
  // Copy the pointers under the lock, send outside it.
  std::vector<std::shared_ptr<LiveSession>> targets;
  {
    std::lock_guard lock(sessions_mutex);
    for (auto& w : live)
      if (auto s = w.lock()) targets.push_back(std::move(s));
  }
  for (auto& s : targets) s->enqueue(message);
}

void HttpServer::Impl::tick_telemetry() {
  const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(1.0 / config.live_rate_hz));
  telemetry_timer.expires_after(period);
  telemetry_timer.async_wait([this](beast::error_code ec) {
    if (ec || stopping) return;
    bool any = false;
    {
      std::lock_guard lock(sessions_mutex);
      for (const auto& w : live) any = any || !w.expired();
    }
    // About once a second: close the sockets whose browser session has ended (sign-out, idle
    // timeout), with close code 4001 so that the page asks to sign in again.
    if (any && ++ticks % std::max(1, static_cast<int>(config.live_rate_hz)) == 0) close_ended_sessions();
    if (any) {
      json t = sequencer.telemetry();
      t["type"] = "telemetry";
      t["seq"] = ++seq;
      t["t"] = iso8601_utc(now_unix_ms());
      send_to_all(std::make_shared<const std::string>(json_text(t)));
    }
    tick_telemetry();
  });
}

HttpServer::HttpServer(const HttpConfig& config, Api& api, Sequencer& sequencer, const StaticFiles& files)
    : impl_(std::make_unique<Impl>(config, api, sequencer, files)) {}

HttpServer::~HttpServer() { stop(); }

void HttpServer::start(const std::string& host, std::uint16_t port) {
  Impl& s = *impl_;
  beast::error_code ec;
  tcp::endpoint endpoint;
  const auto address = net::ip::make_address(host, ec);
  if (!ec) {
    endpoint = tcp::endpoint(address, port);
  } else {
    tcp::resolver resolver(s.ioc);
    const auto results = resolver.resolve(host, std::to_string(port), ec);
    if (ec || results.empty()) throw std::runtime_error("cannot resolve listen host '" + host + "': " + ec.message());
    endpoint = results.begin()->endpoint();
  }
  auto fail = [&](const char* what) {
    throw std::runtime_error(std::string("cannot listen on ") + host + ":" + std::to_string(port) + ": " + what + ": " +
                             ec.message());
  };
  s.acceptor.open(endpoint.protocol(), ec);
  if (ec) fail("open");
  s.acceptor.set_option(net::socket_base::reuse_address(true), ec);
  s.acceptor.bind(endpoint, ec);
  if (ec) fail("bind");
  s.acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) fail("listen");
  s.port = s.acceptor.local_endpoint().port();
  s.accept();
  s.tick_telemetry();
  for (int i = 0; i < s.config.threads; ++i) s.threads.emplace_back([&s] { s.ioc.run(); });
}

std::uint16_t HttpServer::port() const { return impl_->port; }

void HttpServer::broadcast_event(const json& event) {
  Impl& s = *impl_;
  if (s.stopping) return;
  json e = event;
  e["seq"] = ++s.seq;
  e["t"] = iso8601_utc(now_unix_ms());
  s.send_to_all(std::make_shared<const std::string>(json_text(e)));
}

void HttpServer::stop() {
  Impl& s = *impl_;
  if (s.stopping.exchange(true)) return;
  net::post(s.ioc, [&s] {
    beast::error_code ignored;
    s.acceptor.close(ignored);
    s.telemetry_timer.cancel();
    std::vector<std::shared_ptr<LiveSession>> live;
    std::vector<std::shared_ptr<HttpSession>> http_sessions;
    {
      std::lock_guard lock(s.sessions_mutex);
      for (auto& w : s.live)
        if (auto p = w.lock()) live.push_back(std::move(p));
      for (auto& w : s.http_sessions)
        if (auto p = w.lock()) http_sessions.push_back(std::move(p));
    }
    for (auto& p : live) p->close();
    for (auto& p : http_sessions) p->close();
  });
  // Give the closing handshakes a moment, then stop whatever is left.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  while (!s.ioc.stopped() && std::chrono::steady_clock::now() < deadline && !s.threads.empty())
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  s.ioc.stop();
  for (auto& t : s.threads)
    if (t.joinable()) t.join();
  s.threads.clear();
}

}  // namespace imucal::daemon
