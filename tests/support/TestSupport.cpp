// The non-template functions of TestSupport.h, compiled once into the test support library rather than
// into every test file that includes the header.
#include "TestSupport.h"

namespace duplex::test {

TempDir::TempDir() {
  static std::atomic<int> counter{0};
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = "duplex_unit_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
  if (info) name += std::string("_") + info->test_suite_name() + "_" + info->name();
  for (char& c : name)
    if (c == '/') c = '_';
  path_ = std::filesystem::temp_directory_path() / name;
  std::filesystem::remove_all(path_);
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::shared_ptr<const TriangleMesh> sharedMeshCached(const std::string& relative) {
  static std::map<std::string, std::shared_ptr<const TriangleMesh>> cache;
  const auto it = cache.find(relative);
  if (it != cache.end()) return it->second;
  const auto path = sharedMesh(relative);
  if (!path) return nullptr;
  auto mesh = std::make_shared<const TriangleMesh>(loadMesh(*path));
  cache.emplace(relative, mesh);
  return mesh;
}

TriangleMesh icosphere(int subdivisions, double radius, glm::dvec3 centre) {
  const double g = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<glm::dvec3> p = {{-1, g, 0},  {1, g, 0},  {-1, -g, 0}, {1, -g, 0}, {0, -1, g},  {0, 1, g},
                               {0, -1, -g}, {0, 1, -g}, {g, 0, -1},  {g, 0, 1},  {-g, 0, -1}, {-g, 0, 1}};
  for (auto& q : p) q = glm::normalize(q);
  std::vector<TriangleMesh::Triangle> t = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                           {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                           {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                           {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      p.push_back(glm::normalize(p[a] + p[b]));
      const auto id = static_cast<std::uint32_t>(p.size() - 1);
      mid.emplace(key, id);
      return id;
    };
    std::vector<TriangleMesh::Triangle> next;
    next.reserve(t.size() * 4);
    for (const auto& tri : t) {
      const std::uint32_t a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]), c = midpoint(tri[2], tri[0]);
      next.push_back({tri[0], a, c});
      next.push_back({tri[1], b, a});
      next.push_back({tri[2], c, b});
      next.push_back({a, b, c});
    }
    t = std::move(next);
  }
  std::vector<glm::vec3> positions;
  positions.reserve(p.size());
  for (const auto& q : p) positions.emplace_back(centre + radius * q);
  return TriangleMesh::fromTriangles(std::move(positions), std::move(t), "icosphere");
}

TriangleMesh uvSphere(int slices, int stacks, double radius, glm::dvec3 centre) {
  std::vector<glm::vec3> p;
  std::vector<TriangleMesh::Triangle> t;
  p.emplace_back(centre + glm::dvec3(0, 0, radius));  // north pole 0
  for (int i = 1; i < stacks; ++i) {
    const double theta = std::numbers::pi * i / stacks;
    for (int j = 0; j < slices; ++j) {
      const double phi = 2.0 * std::numbers::pi * j / slices;
      p.emplace_back(centre + radius * glm::dvec3(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                                                  std::cos(theta)));
    }
  }
  p.emplace_back(centre + glm::dvec3(0, 0, -radius));  // south pole
  const auto south = static_cast<std::uint32_t>(p.size() - 1);
  auto ring = [&](int i, int j) { return static_cast<std::uint32_t>(1 + (i - 1) * slices + (j % slices)); };
  for (int j = 0; j < slices; ++j) t.push_back({0, ring(1, j), ring(1, j + 1)});
  for (int i = 1; i + 1 < stacks; ++i)
    for (int j = 0; j < slices; ++j) {
      t.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      t.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  for (int j = 0; j < slices; ++j) t.push_back({ring(stacks - 1, j), south, ring(stacks - 1, j + 1)});
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), "uvsphere");
}

TriangleMesh flatGrid(int n, int axis, float level, float cell) {
  std::vector<glm::vec3> p;
  std::vector<TriangleMesh::Triangle> t;
  const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j) {
      glm::vec3 q(0.0f);
      q[axis] = level;
      q[a1] = static_cast<float>(i) * cell;
      q[a2] = static_cast<float>(j) * cell;
      p.push_back(q);
    }
  auto id = [&](int i, int j) { return static_cast<std::uint32_t>(i * (n + 1) + j); };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      t.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      t.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), "flat-grid");
}

TriangleMesh boxMesh(glm::vec3 lo, glm::vec3 hi, std::string name) {
  std::vector<glm::vec3> p;
  for (int i = 0; i < 8; ++i) p.emplace_back(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z);
  std::vector<TriangleMesh::Triangle> t = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                                           {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), std::move(name));
}

TriangleMesh triangleSoup(std::size_t count, std::uint64_t seed, std::string name) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  std::uniform_int_distribution<int> kind(0, 9);
  std::vector<glm::vec3> p;
  std::vector<TriangleMesh::Triangle> t;
  while (t.size() < count) {
    const glm::vec3 c = draw3(u01, rng);
    const int k = kind(rng);
    const float size = k == 0 ? 0.5f : (k < 3 ? 0.1f : 0.03f);
    glm::vec3 v[3];
    for (auto& q : v) q = c + size * (draw3(u01, rng) - 0.5f);
    if (k == 3 || k == 4) {
      // Axis-aligned: all three corners on one of 8 levels of one axis.
      const int axis = static_cast<int>(rng() % 3);
      const float level = static_cast<float>(rng() % 8) / 8.0f;
      for (auto& q : v) q[axis] = level;
    }
    if (k == 5) v[2] = v[0] + (v[1] - v[0]) * 0.5f + glm::vec3(1e-4f, 0.0f, 0.0f);  // sliver
    const glm::dvec3 n = glm::cross(glm::dvec3(v[1]) - glm::dvec3(v[0]), glm::dvec3(v[2]) - glm::dvec3(v[0]));
    if (n == glm::dvec3(0.0)) continue;
    const auto base = static_cast<std::uint32_t>(p.size());
    p.insert(p.end(), v, v + 3);
    t.push_back({base, base + 1, base + 2});
  }
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), std::move(name));
}

std::vector<std::array<glm::vec3, 3>> randomTriangles(std::size_t count, std::uint64_t seed) {
  const TriangleMesh soup = triangleSoup(count, seed);
  std::vector<std::array<glm::vec3, 3>> tris(soup.triangleCount());
  for (std::size_t i = 0; i < tris.size(); ++i) tris[i] = soup.vertices(i);
  return tris;
}

std::array<double, 12> rotationScaleTranslation(glm::dvec3 axis, double angle, glm::dvec3 scale,
                                                glm::dvec3 translation) {
  axis = glm::normalize(axis);
  const double c = std::cos(angle), s = std::sin(angle), C = 1.0 - c;
  const double x = axis.x, y = axis.y, z = axis.z;
  const double r[3][3] = {{c + x * x * C, x * y * C - z * s, x * z * C + y * s},
                          {y * x * C + z * s, c + y * y * C, y * z * C - x * s},
                          {z * x * C - y * s, z * y * C + x * s, c + z * z * C}};
  std::array<double, 12> m{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m[i * 4 + j] = r[i][j] * scale[j];
    m[i * 4 + 3] = translation[i];
  }
  return m;
}

}  // namespace duplex::test
