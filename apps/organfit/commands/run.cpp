// `organfit run SCENE --out DIR` and `organfit validate SCENE`: a scene file, with --set
// overrides checked as the file is (pipeline/runner.h).
#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "commands.h"
#include "organfit/pipeline/runner.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/interrupt.h"

namespace organfit::app {

std::vector<Command> add_run(CLI::App& app, const GlobalOptions& global) {
  struct Options {
    std::string scene_file, out_dir;
    std::vector<std::string> overrides;
  };
  auto o = std::make_shared<Options>();
  auto add_set = [o](CLI::App* command) {
    command
        ->add_option("--set", o->overrides,
                     "section.key=value: sets a scene key for this run (repeatable; validated "
                     "as the file is; recorded in resolved.yaml)")
        ->expected(1)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  };
  auto* run = app.add_subcommand("run", "Run a scene: the stages it names, outputs into --out");
  run->add_option("scene", o->scene_file, "Scene file (YAML)")->required();
  add_set(run);
  run->add_option("-o,--out", o->out_dir, "Output folder (created; not the scene's folder)")
      ->required();

  auto* validate = app.add_subcommand("validate", "Check a scene without running it");
  validate->add_option("scene", o->scene_file, "Scene file (YAML)")->required();
  add_set(validate);

  return {{run,
           [o, &global] {
             const auto scene = pipeline::load_and_check_scene(o->scene_file, o->overrides);
             set_wall_budget(scene.number("scene", "max_wall_s"), "scene.max_wall_s");
             pipeline::RunOptions run_options;
             run_options.show_phi = global.show_phi;
             pipeline::run_scene(scene, o->out_dir, run_options);
             spdlog::info("done: {}/run.json", o->out_dir);
             return 0;
           }},
          {validate, [o] {
             const auto scene = pipeline::load_and_check_scene(o->scene_file, o->overrides);
             std::cout << o->scene_file << ": valid (" << scene.sections().size() << " sections)\n";
             return 0;
           }}};
}

}  // namespace organfit::app
