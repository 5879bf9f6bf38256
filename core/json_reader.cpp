#include "core/json_reader.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

#include "core/nearest_word.hpp"

namespace imucal {

using nlohmann::json;

std::string json_type_name(const json& value) {
  switch (value.type()) {
    case json::value_t::null: return "null";
    case json::value_t::object: return "an object";
    case json::value_t::array: return "an array";
    case json::value_t::string: return "a string";
    case json::value_t::boolean: return "a boolean";
    case json::value_t::number_integer:
    case json::value_t::number_unsigned:
    case json::value_t::number_float: return "a number";
    default: return "an unsupported value";
  }
}

namespace {

std::string not_an_object(const std::string& where, const json& value) {
  return (where.empty() ? std::string("the document") : where) + " must be an object, not " + json_type_name(value);
}

}  // namespace

ObjectReader::ObjectReader(const json& object, std::string where, std::vector<std::string>& problems)
    : where_(std::move(where)), problems_(&problems) {
  if (object.is_object()) {
    object_ = &object;
  } else {
    problem(not_an_object(where_, object));
  }
}

ObjectReader::ObjectReader(const json& object, std::string where, ThrowAtFirst mode)
    : where_(std::move(where)), throw_prefix_(std::move(mode.prefix)) {
  if (!object.is_object()) fail(not_an_object(where_, object));
  object_ = &object;
}

ObjectReader::~ObjectReader() {
  if (problems_ != nullptr) finish();
}

void ObjectReader::problem(const std::string& text) {
  if (problems_ == nullptr) fail(text);
  problems_->push_back(text);
}

void ObjectReader::fail(const std::string& text) const {
  if (problems_ != nullptr) throw std::logic_error("ObjectReader::fail on a collecting reader: " + text);
  throw std::invalid_argument(throw_prefix_ + text);
}

bool ObjectReader::has(const char* key) const { return object_ != nullptr && object_->contains(key); }

const json* ObjectReader::get(const char* key, bool required) {
  if (object_ == nullptr) return nullptr;
  known_.insert(key);
  const auto it = object_->find(key);
  if (it == object_->end()) {
    if (required) problem(at(key) + " is required");
    return nullptr;
  }
  return &*it;
}

std::optional<double> ObjectReader::number(const char* key, bool required) {
  const json* v = get(key, required);
  if (v == nullptr) return std::nullopt;
  if (!v->is_number()) {
    problem(at(key) + " must be a number, not " + json_type_name(*v));
    return std::nullopt;
  }
  const double x = v->get<double>();
  if (!std::isfinite(x)) {
    problem(at(key) + " must be finite");
    return std::nullopt;
  }
  return x;
}

std::optional<double> ObjectReader::number_in(const char* key, double min, std::optional<double> max, bool required) {
  const auto x = number(key, required);
  if (!x) return std::nullopt;
  if (*x < min || (max && *x > *max)) {
    std::string range = max ? "between " + json(min).dump() + " and " + json(*max).dump() : "at least " + json(min).dump();
    problem(at(key) + " is " + json(*x).dump() + ", must be " + range);
    return std::nullopt;
  }
  return x;
}

std::optional<std::int64_t> ObjectReader::integer(const char* key, std::int64_t min, std::int64_t max, bool required) {
  const json* v = get(key, required);
  if (v == nullptr) return std::nullopt;
  if (!v->is_number_integer()) {
    problem(at(key) + " must be an integer, not " + json_type_name(*v));
    return std::nullopt;
  }
  // Unsigned values above int64 range read as negative here and fail the range check below.
  const auto x = v->get<std::int64_t>();
  if (x < min || x > max) {
    problem(at(key) + " is " + std::to_string(x) + ", must be between " + std::to_string(min) + " and " +
                        std::to_string(max));
    return std::nullopt;
  }
  return x;
}

std::optional<std::string> ObjectReader::string(const char* key, bool required) {
  const json* v = get(key, required);
  if (v == nullptr) return std::nullopt;
  if (!v->is_string()) {
    problem(at(key) + " must be a string, not " + json_type_name(*v));
    return std::nullopt;
  }
  return v->get<std::string>();
}

std::optional<bool> ObjectReader::boolean(const char* key, bool required) {
  const json* v = get(key, required);
  if (v == nullptr) return std::nullopt;
  if (!v->is_boolean()) {
    problem(at(key) + " must be true or false, not " + json_type_name(*v));
    return std::nullopt;
  }
  return v->get<bool>();
}

const json& ObjectReader::required(const char* key) {
  if (const json* v = get(key, true)) return *v;
  fail(at(key) + " is required");
}

double ObjectReader::required_number(const char* key) {
  if (const auto v = number(key, true)) return *v;
  fail(at(key) + " is required: a finite number");
}

double ObjectReader::required_number_in(const char* key, double min, std::optional<double> max) {
  if (const auto v = number_in(key, min, max, true)) return *v;
  fail(at(key) + " is required: a number in range");
}

std::int64_t ObjectReader::required_integer(const char* key, std::int64_t min, std::int64_t max) {
  if (const auto v = integer(key, min, max, true)) return *v;
  fail(at(key) + " is required: an integer in range");
}

std::string ObjectReader::required_string(const char* key) {
  if (auto v = string(key, true)) return std::move(*v);
  fail(at(key) + " is required: a string");
}

void ObjectReader::finish() {
  if (finished_ || object_ == nullptr) return;
  finished_ = true;
  for (const auto& [key, value] : object_->items()) {
    if (!key.empty() && key.front() == '_') continue;
    if (known_.count(key) == 0) problem((where_.empty() ? "" : where_ + ": ") + "unknown key \"" + key + "\"");
  }
}

void ObjectReader::finish_extensible() {
  if (finished_ || object_ == nullptr) return;
  finished_ = true;
  // Only a key asked for and absent can be what a foreign key misspells.
  std::vector<std::string> absent;
  for (const std::string& k : known_)
    if (!object_->contains(k)) absent.push_back(k);
  for (const auto& [key, value] : object_->items()) {
    if (known_.count(key) != 0 || key.empty() || key.front() == '_') continue;
    if (const auto near = nearest_word(key, absent))
      problem((where_.empty() ? "" : where_ + ": ") + "unknown key \"" + key + "\" (is it \"" + *near + "\"?)");
  }
}

void read_milliseconds(ObjectReader& r, const char* key, std::chrono::milliseconds& out) {
  if (const auto v = r.integer(key, 1, 3'600'000)) out = std::chrono::milliseconds(*v);
}

}  // namespace imucal
