// libFuzzer target of the strict mesh readers, one executable per format (DUPLEX_FUZZ_FORMAT is
// the mesh_files::Format enumerator's name): the whole input is the file. A FileError (or the
// InvalidArgument of a mesh without a valid triangle, which loadMesh turns into a FileError) is
// the expected refusal; anything else (a crash, a sanitizer report, another exception) is a finding.

#include "MeshFileReaders.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"
#include "duplex/objects/TriangleMesh.h"

#include <cstdint>
#include <cstdlib>
#include <string_view>
#include <utility>

// The library's warnings (degenerate triangles) would be printed for most inputs: silenced.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  duplex::logger()->set_level(spdlog::level::off);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using duplex::mesh_files::Format;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    auto mesh = duplex::mesh_files::read(Format::DUPLEX_FUZZ_FORMAT, bytes, "fuzz-input");
    if (!mesh.triangles.empty())
      (void)duplex::TriangleMesh::fromTriangles(std::move(mesh.positions), std::move(mesh.triangles), "fuzz-input");
  } catch (const duplex::FileError&) {
  } catch (const duplex::InvalidArgument&) {
  }
  return 0;
}
