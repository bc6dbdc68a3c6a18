#pragma once
/// \file StructureOption.h
/// The --structure option of the commands that load scenes: the structure choice of the entries
/// that make none (SceneDocumentOptions::structure), spelt as the scene files' "structure" key.

#include <duplex/accel/Error.h>
#include <duplex/objects/MeshTypes.h>

#include <CLI/CLI.hpp>

#include <string>

namespace duplex::cli {

/// Adds --structure to `cmd`, stored in `structure`; a value the mesh type cannot parse is refused
/// while the command line is parsed.
inline CLI::Option* addStructureOption(CLI::App& cmd, std::string& structure) {
  return cmd
      .add_option("--structure", structure,
                  "Mesh structure of the objects whose entry names none: bvh (default), kdtree, or "
                  "bvh:<preset and parameters> (bvh:fast, bvh:high, bvh:medium,leaf=4)")
      ->check(
          [](const std::string& value) {
            try {
              (void)parseMeshStructureChoice(value);
            } catch (const InvalidArgument& e) {
              return std::string(e.what());
            }
            return std::string();
          },
          "STRUCTURE");
}

}  // namespace duplex::cli
