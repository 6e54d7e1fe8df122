#pragma once
// The scene schema of organfit: every key a scene may use, declared once, in
// src/scene_schema.cpp. `organfit schema` prints it.
#include <string>
#include <vector>

#include "organfit/config/scene.h"

namespace organfit::pipeline {

/// The schema (built once, lives for the process).
const config::Schema& scene_schema();

/// Loads a scene file and applies the rules that tie keys together (m < n, ...).
/// Throws InputError "file:line: key: reason".
config::Scene load_and_check_scene(const std::filesystem::path& file,
                                   const std::vector<std::string>& overrides = {});

/// The cross-key rules alone (for scenes parsed from text in tests).
void check_scene_rules(const config::Scene& scene);

}  // namespace organfit::pipeline
