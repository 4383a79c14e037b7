// The mutable half of a cloth: its state, one row per vertex (the constant half is
// cloth_model.h's). The cloth's stages change v so that the candidates x + dt v respect them
// all; only update_positions (integrators.h) moves x.
#pragma once

#include "math/types.h"

namespace simbake {

struct ClothData {
  Points x;  // (n x 3) positions (m)
  Points v;  // (n x 3) velocities (m/s)
};

}  // namespace simbake
