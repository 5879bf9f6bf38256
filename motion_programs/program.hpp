// Table motion programs as data. A program (JSON, documented in docs/programs.md) is compiled
// into pieces, each with one analytic angle function per axis, so that the true angles, rates
// and accelerations are known exactly at any time: the simulator integrates them by quadrature,
// never by differencing sampled angles. Pure functions of time; no I/O, no clock.
#pragma once

#include <array>
#include <limits>
#include <string>
#include <vector>

#include "core/recording.hpp"
#include "core/table.hpp"

namespace imucal::motion {

struct AxisLimits {
  double min_deg = -std::numeric_limits<double>::infinity();  // unlimited: slip rings
  double max_deg = std::numeric_limits<double>::infinity();
  double rate_dps = 300.0;
  double accel_dps2 = 300.0;
};

struct TableLimits {
  std::array<AxisLimits, 3> axis;  // outer, middle, inner
};

inline constexpr std::array<const char*, 3> kAxisNames = {"outer", "middle", "inner"};

// One axis over one piece, as a function of tau = t - piece.t0_s (radians).
struct AxisFunc {
  enum class Kind { Const, Cycloid, Quadratic, Sine } kind = Kind::Const;
  double theta0 = 0;     // angle at tau = 0
  double delta = 0;      // Cycloid: total change over the piece
  double duration = 0;   // Cycloid, Sine: the piece's length
  double omega0 = 0;     // Quadratic: rate at tau = 0
  double alpha = 0;      // Quadratic: constant acceleration
  double amp = 0;        // Sine: amplitude
  double omega = 0;      // Sine: angular frequency, rad/s
  double phase = 0;      // Sine: phase at tau = 0
  double ramp = 0;       // Sine: length of the smooth amplitude envelope at each end (0: none)

  // angle, rate, acceleration at tau
  void eval(double tau, double& angle, double& rate, double& accel) const;

  // The kinds the programs and the simulated servo build alike (one factory for both).
  static AxisFunc constant(double theta0_rad);
  static AxisFunc quadratic(double theta0_rad, double omega0_rps, double alpha_rps2);
  // The same motion with its time origin moved forward by dt (exact for Const, Quadratic and
  // Sine; a Cycloid, which the servo never produces, is returned as it is).
  AxisFunc rebased(double dt_s) const;
};

struct Piece {
  double t0_s = 0, t1_s = 0;
  std::string segment;  // name of the segment it belongs to
  std::string kind;     // static, rate, sine, coning, tilt, move
  std::array<AxisFunc, 3> axis;
};

class Program {
 public:
  std::string name;
  std::string source_json;  // the program as given (for the run record)
  std::vector<Piece> pieces;

  double duration_s() const { return pieces.empty() ? 0.0 : pieces.back().t1_s; }
  // Segments as the recording format lists them: consecutive pieces of one segment merged.
  std::vector<SegmentInfo> segments() const;
  // Exact state at t. Before the start: the start pose at rest; after the end: the end pose.
  table::AxisState evaluate(double t_s) const;
  // Same, with a cursor for sequential access (amortised O(1)).
  table::AxisState evaluate(double t_s, std::size_t& cursor) const;
  // Times where some angle function is not smooth (piece boundaries, envelope ends), sorted.
  std::vector<double> breakpoints_s() const;
};

// Compile a program from JSON text. Throws std::invalid_argument naming the segment and key.
Program compile_program(const std::string& json_text, const TableLimits& limits);

// Every violation of the table limits (angle range, rate, acceleration per axis) and every rate
// discontinuity, each naming the segment, the axis and the limit. Empty when the program is safe.
std::vector<std::string> validate_program(const Program& program, const TableLimits& limits);

// Built-in programs: direct, direct-short, lever-arm, navigation, noise, evaluate, thermal,
// thermal-short, rate-steps, rate-steps-short, tumble, tumble-short, warm-up, warm-up-short,
// repeatability, repeatability-short (docs/programs.md).
std::vector<std::string> builtin_program_names();
std::string builtin_program_json(const std::string& name);  // throws for an unknown name
// A name of a built-in or a path to a JSON file.
Program load_program(const std::string& name_or_path, const TableLimits& limits);

}  // namespace imucal::motion
