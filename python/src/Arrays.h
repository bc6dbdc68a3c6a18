#pragma once
/// \file Arrays.h
/// NumPy arrays in and out of the bindings: shape and dtype checks with messages that name the
/// argument, rays and points read from float32 or float64 arrays, result arrays allocated in the
/// shape of the input's leading axes. Reading and writing the data runs without the GIL; only
/// allocating and inspecting arrays needs it.

#include <duplex/accel/Affine.h>
#include <duplex/accel/Error.h>
#include <duplex/accel/Ray.h>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace duplex::python {

namespace py = pybind11;

// Arguments that take an array (or anything NumPy or DLPack converts): a py::object that accepts
// every object, read by floatRows() and its kin, whose name in the signatures that help() and
// editors show says the shape and dtype expected (handle_type_name below).
#define DUPLEX_ARRAY_ARGUMENT(Name)                                           \
  class Name : public py::object {                                            \
   public:                                                                    \
    PYBIND11_OBJECT_DEFAULT(Name, py::object, [](PyObject*) { return true; }) \
  };
DUPLEX_ARRAY_ARGUMENT(RaysArray)
DUPLEX_ARRAY_ARGUMENT(PointsArray)
DUPLEX_ARRAY_ARGUMENT(PositionsArray)
DUPLEX_ARRAY_ARGUMENT(TrianglesArray)
DUPLEX_ARRAY_ARGUMENT(TransformArray)
DUPLEX_ARRAY_ARGUMENT(DistanceLimit)
#undef DUPLEX_ARRAY_ARGUMENT

/// The array behind `obj` (NumPy arrays as they are, DLPack tensors through numpy.from_dlpack,
/// sequences converted by NumPy). Throws
/// InvalidArgument naming `what` when NumPy cannot make an array of it.
py::array asArray(const py::object& obj, const char* what);

/// Whether `a` holds float32 or float64 numbers; throws InvalidArgument naming `what` and the
/// dtype otherwise (integers are refused where coordinates are expected: a silent conversion
/// would hide a mistake).
bool isFloat64(const py::array& a, const char* what);

/// The shape of `a` without its last axis, after checking that the last axis has one of the
/// sizes `widths` (InvalidArgument naming `what`, the shape and the expected sizes).
std::vector<py::ssize_t> leadingShape(const py::array& a, std::initializer_list<py::ssize_t> widths, const char* what);

/// Number of elements of an array of shape `shape`.
std::size_t elementCount(const std::vector<py::ssize_t>& shape);

/// `shape` with one more axis of size `n` at the end.
std::vector<py::ssize_t> withAxis(std::vector<py::ssize_t> shape, py::ssize_t n);

/// A C-contiguous float32 or float64 copy (or view) of a coordinate array, kept alive while the
/// data is read without the GIL.
struct FloatRows {
  py::array array;                 ///< contiguous, float32 or float64
  const void* data = nullptr;      ///< array's elements (read without the GIL)
  bool f64 = false;                ///< dtype is float64
  std::size_t rows = 0;            ///< elements of the leading axes
  std::size_t width = 0;           ///< size of the last axis
  std::vector<py::ssize_t> shape;  ///< the leading axes (the shape of per-row results)

  /// Element (row, k) as a double.
  [[nodiscard]] double at(std::size_t row, std::size_t k) const {
    const std::size_t i = row * width + k;
    return f64 ? static_cast<const double*>(data)[i] : static_cast<const float*>(data)[i];
  }
};

/// Reads `obj` as rows of `widths` numbers (float32 or float64), e.g. rays (..., 6) or (..., 8).
FloatRows floatRows(const py::object& obj, std::initializer_list<py::ssize_t> widths, const char* what);

/// Rays [first, first + out.size()) of `rows` ([ox, oy, oz, dx, dy, dz] with tnear 0 and tfar
/// +inf, or [..., tnear, tfar]) into `out`: world space, rounded to float32 (the queries'
/// precision). No Python calls: runs without the GIL, on any thread.
void readRays(const FloatRows& rows, std::size_t first, std::span<Ray> out);

/// Every ray of `rows`, read in parallel; call without the GIL.
std::vector<Ray> raysFromRows(const FloatRows& rows);

/// parent_from_local from None (identity) or a (3, 4) or (4, 4) float64-convertible matrix whose
/// last row, for (4, 4), is [0, 0, 0, 1]. Finiteness is checked by the scene graph.
Affine transformFrom(const py::object& obj, const char* what);

/// A new array of `shape` with uninitialised elements of type T.
template <class T>
py::array_t<T> newArray(const std::vector<py::ssize_t>& shape) {
  return py::array_t<T>(shape);
}

/// Runs f() with `nthreads` worker threads (0: all hardware threads). Throws InvalidArgument for
/// a negative count.
template <class F>
void withThreads(int nthreads, F&& f) {
  if (nthreads < 0) throw InvalidArgument("nthreads must be >= 0 (0: all hardware threads)");
  if (nthreads == 0) {
    f();
    return;
  }
  tbb::task_arena arena(nthreads);
  arena.execute(f);
}

/// body(begin, end) over [0, n) in parallel chunks (in the caller's arena).
template <class F>
void parallelRows(std::size_t n, F&& body) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
}

}  // namespace duplex::python

namespace pybind11::detail {
template <>
struct handle_type_name<duplex::python::RaysArray> {
  static constexpr auto name = const_name("numpy.ndarray[float32 | float64, (..., 6) | (..., 8)]");
};
template <>
struct handle_type_name<duplex::python::PointsArray> {
  static constexpr auto name = const_name("numpy.ndarray[float32 | float64, (..., 3)]");
};
template <>
struct handle_type_name<duplex::python::PositionsArray> {
  static constexpr auto name = const_name("numpy.ndarray[float32 | float64, (N, 3)]");
};
template <>
struct handle_type_name<duplex::python::TrianglesArray> {
  static constexpr auto name = const_name("numpy.ndarray[integer, (M, 3)]");
};
template <>
struct handle_type_name<duplex::python::TransformArray> {
  static constexpr auto name = const_name("numpy.ndarray[float64, (3, 4) | (4, 4)] | None");
};
template <>
struct handle_type_name<duplex::python::DistanceLimit> {
  static constexpr auto name = const_name("float | numpy.ndarray[float64, (...)] | None");
};
}  // namespace pybind11::detail
