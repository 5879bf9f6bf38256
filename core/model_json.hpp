// The helpers the imucal-imu-model/1 JSON is read with (core/imu_model.cpp), shared with the
// sections read elsewhere (core/turn_on.cpp). Every section is read by the one strict reader
// (core/json_reader.hpp), throwing at the first problem: the path of what is wrong, then what.
#pragma once

#include <stdexcept>
#include <string>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/json_reader.hpp"

namespace imucal::model_json {

// A reader of the object `j` at `where` ("m.json.gyro"); its problems throw std::invalid_argument,
// which imu_model_from_json_text() passes on as the model's std::runtime_error.
ObjectReader section(const nlohmann::json& j, const std::string& where);
double num(const ObjectReader& r, const nlohmann::json& v, const std::string& path);  // a finite number
// r[key] (three numbers) times scale; zero when absent (a problem when `required`).
Eigen::Vector3d vec3(ObjectReader& r, const char* key, double scale, bool required = false);
// r[key] times scale; zero when absent.
double scalar(ObjectReader& r, const char* key, double scale);
nlohmann::json arr(const Eigen::Vector3d& v, double scale);

// Parses `text` and reads it with `read`; every problem becomes a std::runtime_error beginning with
// `label`: a model file that is wrong is a runtime error of the file, whichever section found it.
template <class Read>
auto read_model_text(const std::string& text, const std::string& label, Read&& read) -> decltype(read(nlohmann::json{})) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    throw std::runtime_error(label + ": not valid JSON: " + e.what());
  }
  try {
    return read(j);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(e.what());
  }
}

}  // namespace imucal::model_json
