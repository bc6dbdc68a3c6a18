#include "duplex/scenegraph/ObjectTypeRegistry.h"

#include "duplex/accel/Error.h"

#include <nlohmann/json.hpp>

#include <cmath>

namespace duplex {

using nlohmann::json;

// ---- ObjectSpecContext ----

void ObjectSpecContext::fail(const std::string& pointer, const std::string& problem) const {
  throw FileError(scene_file.string() + ": " + (pointer.empty() ? "/" : pointer) + ": " + problem);
}

std::filesystem::path ObjectSpecContext::resolve(const std::string& path) const {
  const std::filesystem::path p(path);
  return p.is_relative() ? scene_file.parent_path() / p : p;
}

const json& ObjectSpecContext::member(const json& obj, const std::string& at, const char* key) const {
  if (!obj.is_object()) fail(at, "expected an object");
  const auto it = obj.find(key);
  if (it == obj.end()) fail(at, std::string("missing key \"") + key + "\"");
  return *it;
}

double ObjectSpecContext::number(const json& v, const std::string& at) const {
  if (!v.is_number()) fail(at, "expected a number");
  const double d = v.get<double>();
  if (!std::isfinite(d)) fail(at, "number is not finite");
  return d;
}

double ObjectSpecContext::positiveNumber(const json& v, const std::string& at) const {
  const double d = number(v, at);
  if (!(d > 0.0)) fail(at, "expected a number > 0");
  return d;
}

std::string ObjectSpecContext::string(const json& v, const std::string& at) const {
  if (!v.is_string()) fail(at, "expected a string");
  return v.get<std::string>();
}

std::vector<double> ObjectSpecContext::positiveSizes(const json& v, const std::string& at, std::size_t n) const {
  if (v.is_number()) return std::vector<double>(n, positiveNumber(v, at));
  if (!v.is_array() || v.size() != n) fail(at, "expected a number or an array of " + std::to_string(n) + " numbers");
  std::vector<double> out;
  for (std::size_t k = 0; k < n; ++k) out.push_back(positiveNumber(v[k], at + "/" + std::to_string(k)));
  return out;
}

void ObjectSpecContext::onlyKeys(const json& obj, const std::string& at,
                                 std::initializer_list<std::string_view> allowed) const {
  if (!strict || !obj.is_object()) return;
  for (const auto& [key, value] : obj.items()) {
    bool known = false;
    for (const std::string_view a : allowed) known = known || key == a;
    if (!known) fail(at + "/" + key, "unknown key \"" + key + "\"");
  }
}

// ---- ObjectTypeRegistry ----

void ObjectTypeRegistry::add(ObjectTypeInfo info) {
  if (info.name.empty()) throw InvalidArgument("ObjectTypeRegistry::add: empty type name");
  if (info.name == "name" || info.name == "structure")
    throw InvalidArgument("ObjectTypeRegistry::add: '" + info.name +
                          "' is a key of every object entry, not a type name");
  if (!info.reader) throw InvalidArgument("ObjectTypeRegistry::add: type '" + info.name + "' has no reader");
  if (find(info.name)) throw InvalidArgument("ObjectTypeRegistry::add: type '" + info.name + "' is already registered");
  types_.push_back(std::move(info));
}

const ObjectTypeInfo* ObjectTypeRegistry::find(std::string_view name) const {
  for (const auto& t : types_)
    if (t.name == name) return &t;
  return nullptr;
}

std::vector<std::string> ObjectTypeRegistry::names() const {
  std::vector<std::string> out;
  for (const auto& t : types_) out.push_back(t.name);
  return out;
}

}  // namespace duplex
