// Triangle index arrays from numpy, checked before the core sees them.
//
// pybind11's Eigen caster converts any numpy array to the core's int32 (m x 3) Triangles with
// numpy's unsafe casting: int64 indices past 2^31 wrap silently (2^32 + 2 becomes 2) and float
// arrays are truncated. This caster takes the place of that one for Triangles only: integer
// arrays whose every value fits in int32 are converted, anything else is ValueError naming the
// problem (an empty array of any type is an empty mesh). Other shapes are not Triangles (the
// call's overload does not match: TypeError), as before. Out, a Triangles is an int32 (m, 3)
// numpy array.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <cstring>
#include <limits>
#include <string>

#include "math/types.h"

namespace pybind11::detail {

template <>
struct type_caster<simbake::Triangles> {
  PYBIND11_TYPE_CASTER(simbake::Triangles, const_name("numpy.ndarray[int32[m, 3]]"));

  bool load(handle src, bool convert) {
    if (!convert && !isinstance<array>(src)) return false;
    array given = array::ensure(src);
    if (!given || given.ndim() != 2 || given.shape(1) != 3) return false;
    if (given.size() > 0) check_indices(given);
    auto indices = array_t<std::int32_t, array::c_style | array::forcecast>::ensure(given);
    if (!indices) return false;
    value.resize(given.shape(0), 3);
    if (given.size() > 0) std::memcpy(value.data(), indices.data(), sizeof(std::int32_t) * given.size());
    return true;
  }

  static handle cast(const simbake::Triangles& src, return_value_policy, handle) {
    array_t<std::int32_t> out({static_cast<ssize_t>(src.rows()), static_cast<ssize_t>(3)});
    if (src.size() > 0) std::memcpy(out.mutable_data(), src.data(), sizeof(std::int32_t) * src.size());
    return out.release();
  }

 private:
  // whole numbers only, each within int32 (a wrapped index would name another vertex)
  static void check_indices(const array& given) {
    const char kind = given.dtype().kind();
    if (kind != 'i' && kind != 'u') {
      throw value_error("triangle indices must be integers, got an array of " +
                        std::string(pybind11::str(given.dtype())));
    }
    const int_ lo = given.attr("min")(), hi = given.attr("max")();
    const bool low = lo < int_(std::numeric_limits<std::int32_t>::min());
    if (low || hi > int_(std::numeric_limits<std::int32_t>::max())) {
      throw value_error("triangle index " + std::string(pybind11::str(low ? lo : hi)) +
                        " does not fit in 32 bits (a mesh has at most 2^31 - 1 vertices)");
    }
  }
};

}  // namespace pybind11::detail
