// Examples for scripts/static/lifetimes.query (not built): scripts/static-check.sh runs the query
// here first; it must find every line marked BAD (but those marked clang Wdangling, which the
// compiler reports) and no line marked ok.
#include <nlohmann/json.hpp>
#include <string>
#include <vector>
#include <optional>
#include <span>
using nlohmann::json;
json make();
std::vector<int> vec();
struct H { std::vector<int> v; const std::vector<int>& get() const { return v; } };
H h();
int f(const json& r) {
  int n = 0;
  for (const auto& [k, v] : r.value("e", json::object()).items()) n++;   // BAD
  for (const auto& [k, v] : make().items()) n++;  // BAD
  for (int x : h().get()) n += x;  // BAD
  for (int x : vec()) n += x;      // ok
  for (const auto& [k, v] : r.at("e").items()) n++;  // ok
  json loc = make();
  for (const auto& [k, v] : loc.items()) n++;  // ok
  for (const auto& x : make()) n++;  // ok
  for (const auto& x : make()["a"]) n++;  // BAD
  std::optional<std::vector<int>> o;
  for (int x : std::optional<std::vector<int>>().value()) n+=x; // BAD
  for (int x : *o) n+=x; // ok
  return n;
}
int g2(json& j) {
  int n = 0;
  for (const auto& x : j[std::string("a")]) n++;  // ok
  for (const auto& x : j.at(std::string("a")).items()) n++;  // ok
  for (auto c : std::string_view(std::string("abc"))) n += c; // BAD (clang Wdangling)
  for (const auto& x : make().at("a").at("b")) n++;  // BAD
  return n;
}
int g3() {
  const json& a = make().at("a");  // BAD
  const json& b = make();          // ok
  auto p = make().items();         // BAD
  const auto& v = vec();           // ok
  const int& e = h().get()[0];     // BAD
  json c = make().at("a");         // ok
  auto n = make().at("a").size();  // ok
  std::vector<int> w = vec();
  auto s = std::span<const int>(w).subspan(1);  // ok
  const int& last = *(w.end() - 1);  // ok
  return last + (int)s.size() + (int)a.size() + (int)b.size() + (int)v.size() + e + (int)c.size() + (int)n + (p.begin() == p.end());
}
