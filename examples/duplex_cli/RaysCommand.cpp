#include "RaysCommand.h"

#include "LoadScene.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/RayFile.h>
#include <duplex/accel/RayGenerator.h>

#include <algorithm>
#include <optional>
#include <span>
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

  // Generated and written a block at a time: memory does not grow with the ray count. The file
  // appears when complete.
  const std::size_t count =
      primary ? static_cast<std::size_t>(*options.width) * *options.height : *options.random_count;
  std::optional<RandomRayStream> random;
  if (!primary) random.emplace(world_bounds, options.seed.value());
  constexpr std::size_t kBlock = std::size_t{1} << 18;
  std::vector<Ray> block(std::min(count, kBlock));
  RecordFileWriter<Ray> out(options.out, "ray");
  for (std::size_t first = 0; first < count; first += kBlock) {
    const std::span<Ray> rays(block.data(), std::min(kBlock, count - first));
    if (primary) primaryRays(world_bounds, *options.width, *options.height, first, rays);
    else random->next(rays);
    out.write(rays);
  }
  out.commit();

  nlohmann::ordered_json summary;
  summary["rays"] = count;
  summary["out"] = options.out.string();
  if (!primary) summary["seed"] = options.seed.value();
  return summary;
}

}  // namespace duplex::cli
