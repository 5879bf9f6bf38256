#include "drivers/embedded_json.hpp"

#include <fstream>
#include <sstream>
#include <stdexcept>

namespace imucal::drivers {

namespace {
std::string joined(std::span<const EmbeddedJson> builtins) {
  std::string s;
  for (const EmbeddedJson& b : builtins) s += (s.empty() ? "" : ", ") + std::string(b.name);
  return s;
}
}  // namespace

std::vector<std::string> embedded_names(std::span<const EmbeddedJson> builtins) {
  std::vector<std::string> names;
  for (const EmbeddedJson& b : builtins) names.emplace_back(b.name);
  return names;
}

std::string embedded_text(std::span<const EmbeddedJson> builtins, const std::string& name, const std::string& what) {
  for (const EmbeddedJson& b : builtins)
    if (name == b.name) return b.json;
  throw std::invalid_argument("unknown built-in " + what + " '" + name + "' (built in: " + joined(builtins) + ")");
}

std::string embedded_or_file_text(std::span<const EmbeddedJson> builtins, const std::string& name_or_path,
                                  const std::string& what) {
  for (const EmbeddedJson& b : builtins)
    if (name_or_path == b.name) return b.json;
  std::ifstream in(name_or_path);
  if (!in)
    throw std::invalid_argument(what + " '" + name_or_path + "': no such built-in one (" + joined(builtins) +
                                ") or file");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace imucal::drivers
