#include "LoadScene.h"

#include <duplex/accel/Error.h>

#include <exception>
#include <string>

namespace duplex::cli {

Scene loadSceneNamed(const std::filesystem::path& path, SceneLoadReport* report) {
  try {
    return loadScene(path, {}, report);
  } catch (const Error&) {
    throw;  // already names the file
  } catch (const std::bad_alloc&) {
    throw;
  } catch (const std::exception& e) {
    throw FileError(path.string() + ": " + e.what());
  }
}

}  // namespace duplex::cli
