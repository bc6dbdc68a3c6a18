// duplex_validate: runs the CIE 171:2006 cases (CieCases.h) at a chosen length and writes every
// value with its reference as JSON, for scripts/validate (which writes docs/validation.md).
//
// Usage: duplex_validate [--scale S] [--threads N] [--out FILE]
//   --scale S   multiplies every case's ray count (default 20; 1 is the CTest length)
//   --threads N worker threads (default 0: all)
//   --out FILE  the JSON (default: stdout)

#include "CieCases.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <string>

int main(int argc, char** argv) {
  using namespace duplex::validation;
  CaseOptions o;
  o.scale = 20.0;
  std::string out;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      std::cerr << "duplex_validate: " << a << " needs a value\n";
      return 2;
    }
    const std::string v = argv[++i];
    try {
      if (a == "--scale") o.scale = std::stod(v);
      else if (a == "--threads") o.threads = static_cast<unsigned>(std::stoul(v));
      else if (a == "--out") out = v;
      else {
        std::cerr << "duplex_validate: unknown option " << a << '\n';
        return 2;
      }
    } catch (const std::exception&) {
      std::cerr << "duplex_validate: " << a << " '" << v << "' is not a number\n";
      return 2;
    }
  }
  if (!(o.scale > 0.0 && std::isfinite(o.scale))) {
    std::cerr << "duplex_validate: --scale must be a positive number\n";
    return 2;
  }
  nlohmann::ordered_json cases = nlohmann::ordered_json::array();
  bool all_pass = true;
  for (const CaseResult& c : allCases(o)) {
    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    for (const CaseRow& r : c.rows) {
      all_pass = all_pass && r.passes();
      rows.push_back(
          {{"label", r.label},
           {"reference", r.reference},
           {"value", r.value},
           {"stderr", r.stderr_value},
           {"z", r.z()},
           {"relative_tolerance", r.relative_tolerance},
           {"passes", r.passes()},
           {"other", std::isnan(r.other) ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(r.other)}});
    }
    cases.push_back({{"name", c.name},
                     {"title", c.title},
                     {"reference", c.reference},
                     {"unit", c.unit},
                     {"rays", c.rays},
                     {"seconds", c.seconds},
                     {"notes", c.notes},
                     {"rows", rows}});
    std::cerr << c.name << ": " << c.rows.size() << " values, " << c.seconds << " s\n";
  }
  const nlohmann::ordered_json report = {{"scale", o.scale}, {"all_pass", all_pass}, {"cases", cases}};
  if (out.empty()) std::cout << report.dump(1) << '\n';
  else std::ofstream(out) << report.dump(1) << '\n';
  return all_pass ? 0 : 1;
}
