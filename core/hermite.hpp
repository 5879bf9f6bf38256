// Cubic Hermite interpolation between two samples of a quantity and its rate of change: exact for
// a cubic, hence for the constant-acceleration pieces a table controller runs between two reads.
// One rule for the table reads a frame's angles come from (daemon/devices/wire_bench.cpp), the
// drivers benchmark's alignment check (bench/) and the simulated thermal truth's grid
// (sim/thermal_model.cpp).
#pragma once

namespace imucal {

// The weights of y0, h*rate0, y1 and h*rate1 at `u` (0..1 across the interval of length h), and of
// their derivative with respect to u.
struct HermiteWeights {
  double h00, h10, h01, h11;
  double d00, d10, d01, d11;
};

inline HermiteWeights hermite_weights(double u) noexcept {
  const double u2 = u * u, u3 = u2 * u;
  return {2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2,
          6 * u2 - 6 * u,      3 * u2 - 4 * u + 1, -6 * u2 + 6 * u, 3 * u2 - 2 * u};
}

// The value at `u` between (y0, rate0) and (y1, rate1), `h` the interval in the rates' time unit.
inline double cubic_hermite(double y0, double rate0, double y1, double rate1, double h, double u) noexcept {
  const HermiteWeights w = hermite_weights(u);
  return w.h00 * y0 + w.h10 * h * rate0 + w.h01 * y1 + w.h11 * h * rate1;
}

// Its rate of change at `u`, in the rates' unit.
inline double cubic_hermite_rate(double y0, double rate0, double y1, double rate1, double h, double u) noexcept {
  const HermiteWeights w = hermite_weights(u);
  return (w.d00 * y0 + w.d01 * y1) / h + w.d10 * rate0 + w.d11 * rate1;
}

}  // namespace imucal
