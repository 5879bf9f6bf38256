// A table of the size issue 34 names (2" tilt, 3" non-perpendicularity, 1" + 0.5" encoder
// harmonics, a phase of its own per axis): one definition for the kinematics tests and stage 3's.
#pragma once

#include <cstddef>

#include "core/table.hpp"
#include "core/units.hpp"

namespace imucal::tabletest {

inline table::TableGeometry imperfect() {
  constexpr double kAs = units::kArcsecToRad;
  table::TableGeometry g;
  g.outer_tilt_rad = {2.0 * kAs, 1.2 * kAs};
  g.middle_axis_rad = {3.0 * kAs, -1.5 * kAs};
  g.inner_axis_rad = {2.1 * kAs, -3.0 * kAs};
  for (std::size_t axis = 0; axis < 3; ++axis)
    g.encoder_error[axis] = {{1, 1.0 * kAs, 0.3 + 0.8 * static_cast<double>(axis)},
                             {2, 0.5 * kAs, 0.6 + 1.6 * static_cast<double>(axis)}};
  return g;
}

}  // namespace imucal::tabletest
