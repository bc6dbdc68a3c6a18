#include "Arrays.h"

#include <xmmintrin.h>

#include <cstddef>
#include <limits>
#include <sstream>

namespace duplex::python {

namespace {

std::string shapeText(const py::array& a) {
  std::ostringstream s;
  s << '(';
  for (py::ssize_t i = 0; i < a.ndim(); ++i) s << (i ? ", " : "") << a.shape(i);
  if (a.ndim() == 1) s << ',';
  s << ')';
  return s.str();
}

std::string dtypeText(const py::array& a) { return py::str(a.dtype()).cast<std::string>(); }

}  // namespace

py::array asArray(const py::object& obj, const char* what) {
  if (obj.is_none()) throw InvalidArgument(std::string(what) + ": expected an array, got None");
  py::array a;
  try {
    // Tensors of other libraries (Open3D's, PyTorch's) that NumPy cannot read through __array__
    // come in through DLPack; without this NumPy would make an array of dtype object of them.
    if (!py::isinstance<py::array>(obj) && !py::hasattr(obj, "__array__") && py::hasattr(obj, "__dlpack__"))
      a = py::module_::import("numpy").attr("from_dlpack")(obj);
    else a = py::array::ensure(obj);
  } catch (const py::error_already_set&) {
    a = py::array();
  }
  if (!a) {
    PyErr_Clear();
    throw InvalidArgument(std::string(what) + ": expected an array (NumPy cannot convert a " +
                          py::str(py::type::of(obj).attr("__name__")).cast<std::string>() + ")");
  }
  return a;
}

bool isFloat64(const py::array& a, const char* what) {
  if (a.dtype().is(py::dtype::of<double>())) return true;
  if (a.dtype().is(py::dtype::of<float>())) return false;
  throw InvalidArgument(std::string(what) + ": dtype " + dtypeText(a) +
                        " is not supported (expected float32 or float64)");
}

std::vector<py::ssize_t> leadingShape(const py::array& a, std::initializer_list<py::ssize_t> widths, const char* what) {
  bool ok = a.ndim() >= 1;
  if (ok) {
    ok = false;
    for (const py::ssize_t w : widths) ok = ok || a.shape(a.ndim() - 1) == w;
  }
  if (!ok) {
    std::string expected;
    for (const py::ssize_t w : widths)
      expected += (expected.empty() ? "(..., " : " or (..., ") + std::to_string(w) + ")";
    throw InvalidArgument(std::string(what) + ": shape " + shapeText(a) + " is not " + expected);
  }
  return {a.shape(), a.shape() + a.ndim() - 1};
}

std::size_t elementCount(const std::vector<py::ssize_t>& shape) {
  std::size_t n = 1;
  for (const py::ssize_t s : shape) n *= static_cast<std::size_t>(s);
  return n;
}

std::vector<py::ssize_t> withAxis(std::vector<py::ssize_t> shape, py::ssize_t n) {
  shape.push_back(n);
  return shape;
}

FloatRows floatRows(const py::object& obj, std::initializer_list<py::ssize_t> widths, const char* what) {
  const py::array a = asArray(obj, what);
  FloatRows out;
  out.f64 = isFloat64(a, what);
  out.shape = leadingShape(a, widths, what);
  out.rows = elementCount(out.shape);
  out.width = static_cast<std::size_t>(a.shape(a.ndim() - 1));
  // A view when already C-contiguous, else one copy.
  if (out.f64) out.array = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
  else out.array = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(a);
  out.data = out.array.data();
  return out;
}

namespace {

template <class T>
void readRaysOf(const T* data, std::size_t width, std::size_t first, std::span<Ray> out) {
  const T* p = data + first * width;
  for (Ray& r : out) {
    r.origin = {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])};
    r.dir = {static_cast<float>(p[3]), static_cast<float>(p[4]), static_cast<float>(p[5])};
    if (width == 8) {
      r.tnear = static_cast<float>(p[6]);
      r.tfar = static_cast<float>(p[7]);
    } else {
      r.tnear = 0.0f;
      r.tfar = std::numeric_limits<float>::infinity();
    }
    p += width;
  }
}

// The common case, float32 rows of 8: two loads and four shuffles per ray reorder
// [ox oy oz dx | dy dz tnear tfar] into the Ray layout [ox oy oz tnear | dx dy dz tfar] (SSE, which
// every x86-64 processor has).
void readRays8(const float* data, std::size_t first, std::span<Ray> out) {
  static_assert(sizeof(Ray) == 8 * sizeof(float) && offsetof(Ray, tnear) == 3 * sizeof(float) &&
                offsetof(Ray, dir) == 4 * sizeof(float) && offsetof(Ray, tfar) == 7 * sizeof(float));
  const float* p = data + first * 8;
  auto* r = reinterpret_cast<float*>(out.data());
  for (std::size_t i = 0; i < out.size(); ++i, p += 8, r += 8) {
    const __m128 a = _mm_loadu_ps(p);                                     // ox oy oz dx
    const __m128 b = _mm_loadu_ps(p + 4);                                 // dy dz tn tf
    const __m128 c = _mm_shuffle_ps(a, b, _MM_SHUFFLE(3, 2, 3, 2));       // oz dx tn tf
    const __m128 d = _mm_shuffle_ps(a, b, _MM_SHUFFLE(1, 0, 3, 3));       // dx dx dy dz
    _mm_storeu_ps(r, _mm_shuffle_ps(a, c, _MM_SHUFFLE(2, 0, 1, 0)));      // ox oy oz tn
    _mm_storeu_ps(r + 4, _mm_shuffle_ps(d, b, _MM_SHUFFLE(3, 1, 2, 0)));  // dx dy dz tf
  }
}

}  // namespace

void readRays(const FloatRows& rows, std::size_t first, std::span<Ray> out) {
  if (rows.f64) readRaysOf(static_cast<const double*>(rows.data), rows.width, first, out);
  else if (rows.width == 8) readRays8(static_cast<const float*>(rows.data), first, out);
  else readRaysOf(static_cast<const float*>(rows.data), rows.width, first, out);
}

std::vector<Ray> raysFromRows(const FloatRows& rows) {
  std::vector<Ray> rays(rows.rows);
  parallelRows(rows.rows, [&](std::size_t begin, std::size_t end) {
    readRays(rows, begin, std::span<Ray>(rays.data() + begin, end - begin));
  });
  return rays;
}

Affine transformFrom(const py::object& obj, const char* what) {
  if (obj.is_none()) return Affine::identity();
  const py::array a = asArray(obj, what);
  if (a.dtype().kind() != 'f' && a.dtype().kind() != 'i' && a.dtype().kind() != 'u')
    throw InvalidArgument(std::string(what) + ": dtype " + dtypeText(a) + " is not a number type");
  const auto m = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a);
  const bool square = m.ndim() == 2 && m.shape(0) == 4 && m.shape(1) == 4;
  if (!(m.ndim() == 2 && m.shape(1) == 4 && (m.shape(0) == 3 || square)))
    throw InvalidArgument(std::string(what) + ": shape " + shapeText(a) + " is not (3, 4) or (4, 4)");
  const double* p = m.data();
  if (square && !(p[12] == 0.0 && p[13] == 0.0 && p[14] == 0.0 && p[15] == 1.0))
    throw InvalidArgument(std::string(what) +
                          ": the last row of a (4, 4) transform must be [0, 0, 0, 1] (affine transforms only)");
  std::array<double, 12> rows{};
  for (int i = 0; i < 12; ++i) rows[static_cast<std::size_t>(i)] = p[i];
  return Affine::fromRowMajor3x4(rows);
}

}  // namespace duplex::python
