// `organfit schema [--json]`: every scene key (type, default, unit, range, doc), and
// `organfit version`.
#include <iostream>
#include <memory>

#include "commands.h"
#include "organfit/pipeline/runner.h"
#include "organfit/pipeline/scene_schema.h"

namespace organfit::app {

std::vector<Command> add_schema(CLI::App& app) {
  auto json = std::make_shared<bool>(false);
  auto* schema =
      app.add_subcommand("schema", "Print every scene key: type, default, unit, range, doc");
  schema->add_flag("--json", *json, "As JSON");
  auto* version = app.add_subcommand("version", "Print the organfit version");
  return {{schema,
           [json] {
             const auto& s = pipeline::scene_schema();
             std::cout << (*json ? s.to_json().dump(2) + "\n" : s.to_text());
             return 0;
           }},
          {version, [] {
             std::cout << "organfit " << pipeline::version() << "\n";
             return 0;
           }}};
}

}  // namespace organfit::app
