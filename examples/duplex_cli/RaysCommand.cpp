#include "RaysCommand.h"

#include "LoadScene.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/RayFile.h>
#include <duplex/accel/RayGenerator.h>

#include <vector>

namespace duplex::cli {

nlohmann::ordered_json runRays(const RaysOptions& options) {
  const bool primary = options.width.has_value();
  if (primary == options.random_count.has_value())
    throw InvalidArgument("give exactly one of --primary W H and --random N --seed X");

  const SceneDocument doc = loadDocumentNamed(options.scene, documentOptions(options.structure));
  const Box world_bounds = visibleWorldBounds(doc);
  if (world_bounds.empty())
    throw InvalidArgument(options.scene.string() +
                          ": scene has no visible instances, so no bounds to generate rays in");

  const std::vector<Ray> rays = primary ? primaryRays(world_bounds, *options.width, *options.height)
                                        : randomRays(world_bounds, *options.random_count, options.seed.value());
  writeRayFile(options.out, rays);

  nlohmann::ordered_json summary;
  summary["rays"] = rays.size();
  summary["out"] = options.out.string();
  return summary;
}

}  // namespace duplex::cli
