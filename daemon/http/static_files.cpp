#include "daemon/http/static_files.hpp"

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace imucal::daemon {

namespace fs = std::filesystem;

namespace {
constexpr std::uintmax_t kMaxFileBytes = 64u << 20;

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

HttpReply text_reply(int status, const std::string& text) {
  HttpReply r;
  r.status = status;
  r.body = text + "\n";
  r.content_type = "text/plain; charset=utf-8";
  return r;
}
}  // namespace

bool percent_decode(std::string_view in, std::string& out, bool plus_is_space) {
  out.clear();
  for (std::size_t i = 0; i < in.size(); ++i) {
    const char c = in[i];
    if (c == '%') {
      if (i + 2 >= in.size()) return false;
      const int hi = hex_value(in[i + 1]), lo = hex_value(in[i + 2]);
      if (hi < 0 || lo < 0) return false;
      const char decoded = static_cast<char>(hi * 16 + lo);
      if (decoded == '\0') return false;
      out.push_back(decoded);
      i += 2;
    } else if (c == '+' && plus_is_space) {
      out.push_back(' ');
    } else {
      out.push_back(c);
    }
  }
  return true;
}

const char* content_type_for(std::string_view path) {
  const auto dot = path.rfind('.');
  const std::string_view ext = dot == std::string_view::npos ? std::string_view() : path.substr(dot + 1);
  if (ext == "html" || ext == "htm") return "text/html; charset=utf-8";
  if (ext == "js" || ext == "mjs") return "text/javascript; charset=utf-8";
  if (ext == "css") return "text/css; charset=utf-8";
  if (ext == "json" || ext == "map") return "application/json";
  if (ext == "svg") return "image/svg+xml";
  if (ext == "png") return "image/png";
  if (ext == "jpg" || ext == "jpeg") return "image/jpeg";
  if (ext == "ico") return "image/x-icon";
  if (ext == "woff2") return "font/woff2";
  if (ext == "wasm") return "application/wasm";
  if (ext == "txt") return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

StaticFiles::StaticFiles(const std::string& root) {
  std::error_code ec;
  if (!root.empty() && fs::is_directory(root, ec)) root_ = fs::canonical(root, ec).string();
}

HttpReply StaticFiles::get(std::string_view path, std::string_view if_none_match, bool head) const {
  if (root_.empty()) return text_reply(404, "not found (no web directory configured)");
  std::string decoded;
  if (path.empty() || path.front() != '/' || !percent_decode(path, decoded)) return text_reply(400, "bad path");
  // Refuse anything that could climb out or reach hidden files, before touching the disk.
  if (decoded.find('\\') != std::string::npos) return text_reply(400, "bad path");
  std::string relative;
  std::size_t start = 1;
  while (start <= decoded.size()) {
    const auto end = std::min(decoded.find('/', start), decoded.size());
    const std::string_view segment(decoded.data() + start, end - start);
    if (!segment.empty()) {
      if (segment.front() == '.') return text_reply(404, "not found");
      relative += (relative.empty() ? "" : "/") + std::string(segment);
    }
    start = end + 1;
  }
  if (relative.empty() || decoded.back() == '/') relative += (relative.empty() ? "" : "/") + std::string("index.html");

  std::error_code ec;
  const fs::path full = fs::canonical(fs::path(root_) / relative, ec);
  if (ec) return text_reply(404, "not found");
  const std::string full_text = full.string();
  // A symlink inside the root may point elsewhere: the resolved path must still be inside.
  if (full_text.size() <= root_.size() || full_text.compare(0, root_.size(), root_) != 0 ||
      full_text[root_.size()] != '/')
    return text_reply(404, "not found");
  if (!fs::is_regular_file(full, ec)) return text_reply(404, "not found");
  const auto size = fs::file_size(full, ec);
  if (ec || size > kMaxFileBytes) return text_reply(404, "not found");
  // The file clock's epoch is implementation-defined (counts may be negative): only equality matters.
  const auto mtime = static_cast<std::uint64_t>(fs::last_write_time(full, ec).time_since_epoch().count());

  HttpReply r;
  r.content_type = content_type_for(full_text);
  char etag_text[64];
  std::snprintf(etag_text, sizeof etag_text, "\"%jx-%jx\"", static_cast<std::uintmax_t>(size),
                static_cast<std::uintmax_t>(mtime));
  const std::string etag = etag_text;
  r.headers.emplace_back("ETag", etag);
  // The UI's files have no content hashes in their names: let browsers keep them briefly and
  // revalidate (cheap with the ETag); HTML always revalidates so a new UI shows at once.
  r.headers.emplace_back("Cache-Control", r.content_type.rfind("text/html", 0) == 0 ? "no-cache" : "public, max-age=300");
  r.headers.emplace_back("X-Content-Type-Options", "nosniff");
  if (!if_none_match.empty() && if_none_match == etag) {
    r.status = 304;
    return r;
  }
  if (!head) {
    std::ifstream in(full, std::ios::binary);
    if (!in) return text_reply(404, "not found");
    std::ostringstream content;
    content << in.rdbuf();
    r.body = content.str();
  }
  return r;
}

}  // namespace imucal::daemon
