#pragma once
/// \file LoadScene.h
/// duplex::loadScene with every failure reported as a duplex::FileError naming the scene file.

#include <duplex/scenegraph/SceneFile.h>

#include <filesystem>

namespace duplex::cli {

/// Same as duplex::loadScene with default options. Some failures reach callers of loadScene as
/// other exceptions (e.g. nlohmann's out_of_range for a number such as 1e999); they are rethrown
/// as FileError("<file>: <what>") so that the tool's message always names the file.
[[nodiscard]] Scene loadSceneNamed(const std::filesystem::path& path, SceneLoadReport* report = nullptr);

}  // namespace duplex::cli
