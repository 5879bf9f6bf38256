// The readers the imucal-imu-model/1 JSON is parsed with (core/imu_model.cpp), shared with the
// sections parsed elsewhere (core/turn_on.cpp), so that every section reports a wrong key or
// value the same way: the path of what is wrong, then what.
#pragma once

#include <initializer_list>
#include <string>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace imucal::model_json {

[[noreturn]] void fail(const std::string& where, const std::string& what);
// An object whose keys are all in `allowed` (a typo must not become a silent zero).
void check_keys(const nlohmann::json& j, const std::string& where, std::initializer_list<const char*> allowed);
double num(const nlohmann::json& j, const std::string& where);  // a finite number
// j[key] (three numbers) times scale; zero when absent.
Eigen::Vector3d vec3(const nlohmann::json& j, const char* key, const std::string& where, double scale);
// j[key] times scale; zero when absent.
double scalar(const nlohmann::json& j, const char* key, const std::string& where, double scale);
nlohmann::json arr(const Eigen::Vector3d& v, double scale);

}  // namespace imucal::model_json
