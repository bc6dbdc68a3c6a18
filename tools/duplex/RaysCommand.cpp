#include "RaysCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "StructureOption.h"
#include "LoadScene.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/RayFile.h>
#include <duplex/accel/RayGenerator.h>

#include <algorithm>
#include <iostream>
#include <memory>
#include <optional>
#include <span>
#include <string>
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

namespace {

// The seed of `duplex rays --random` without --seed (reported in the JSON and on stderr).
constexpr std::uint64_t kDefaultRaySeed = 1;

}  // namespace

void addRaysCommand(CLI::App& parent, ChosenCommand& chosen) {
  // The options as given; the callback turns them into RaysOptions.
  struct Given {
    RaysOptions rays;
    std::vector<std::uint32_t> primary;
    std::uint64_t random_count = 0, seed = 0;
  };
  auto given = std::make_shared<Given>();
  CLI::App* cmd = parent.add_subcommand("rays", "Write primary or random rays for a scene");
  cmd->add_option("--scene", given->rays.scene,
                  "scene-json-v1 or duplex-scene-v1 file (the world bounds of its visible instances place the rays)")
      ->required();
  cmd->add_option("--out", given->rays.out, "Ray file to write")->required();
  addStructureOption(*cmd, given->rays.structure);
  CLI::Option* primary_opt =
      cmd->add_option("--primary", given->primary, "W H: primary rays of a W x H image, row-major from the top left")
          ->expected(2)
          ->transform(kDecimal)
          ->check(CLI::Range(1u, 65536u));
  CLI::Option* random_opt = cmd->add_option("--random", given->random_count, "N random rays (origins in the world box)")
                                ->transform(kDecimal)
                                ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 32));
  CLI::Option* seed_opt =
      cmd->add_option("--seed", given->seed,
                      "Seed of the random rays (0 to 2^64-1; default " + std::to_string(kDefaultRaySeed) + ")")
          ->transform(kDecimal);
  primary_opt->excludes(random_opt);
  primary_opt->excludes(seed_opt);
  seed_opt->needs(random_opt);
  onParsed(*cmd, chosen, given, [primary_opt, random_opt, seed_opt](const Given& g) {
    RaysOptions rays = g.rays;
    if (*primary_opt) {
      rays.width = g.primary[0];
      rays.height = g.primary[1];
    }
    if (*random_opt) {
      rays.random_count = g.random_count;
      rays.seed = *seed_opt ? g.seed : kDefaultRaySeed;
      if (!*seed_opt) std::cerr << "duplex rays: no --seed given; using the default seed " << kDefaultRaySeed << "\n";
    }
    return runRays(rays);
  });
}

}  // namespace duplex::cli
