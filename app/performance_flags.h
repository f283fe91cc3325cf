// The command-line flags of a simulated performance (expression, head motion, duration, seed),
// shared by `facedyn sim perform` (the world's subject) and `facedyn twin perform` (the fitted
// twin), which differ only in where the tissue comes from.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "sim/performance.h"

namespace facedyn::app {

// Adds --expression, --motion (into *motion_spec, parsed by sim::ParseMotionKind), --hz,
// --amplitude-mm, --head-hz, --head-deg, --sway-mm, --lie-back-deg, --lie-back-s, --seconds, --fps
// and --seed to `command`.
inline void AddPerformanceFlags(CLI::App* command, sim::PerformanceOptions* p,
                                std::string* motion_spec) {
  command
      ->add_option("--expression", p->expression,
                   "Expression name, or 'speech' or 'range_of_motion'")
      ->capture_default_str();
  command
      ->add_option("--motion", *motion_spec,
                   "platform | walk | run | jump | nod | shake | sway | turn_walk | lie_back | "
                   "none | file:SKULL.csv")
      ->capture_default_str();
  command->add_option("--hz", p->motion.platform_hz, "Platform frequency (Hz)")
      ->capture_default_str();
  command->add_option("--amplitude-mm", p->motion.amplitude_mm, "Platform amplitude (mm, peak)")
      ->capture_default_str();
  command
      ->add_option("--head-hz", p->motion.head_motion_hz,
                   "Nod, shake, sway or turn_walk's head-turn frequency (Hz)")
      ->capture_default_str();
  command
      ->add_option("--head-deg", p->motion.head_motion_deg,
                   "Nod, shake or turn_walk's head-turn amplitude (degrees, peak)")
      ->capture_default_str();
  command->add_option("--sway-mm", p->motion.head_sway_mm, "Sway: lateral amplitude (mm, peak)")
      ->capture_default_str();
  command
      ->add_option("--lie-back-deg", p->motion.lie_back_deg,
                   "Lie_back: how far the subject lies back (degrees from upright)")
      ->capture_default_str();
  command
      ->add_option("--lie-back-s", p->motion.lie_back_s, "Lie_back: duration of the transition (s)")
      ->capture_default_str();
  command->add_option("--seconds", p->seconds, "Duration (s)")->capture_default_str();
  command->add_option("--fps", p->fps, "Frame rate")->capture_default_str();
  command->add_option("--seed", p->seed, "Random seed (expression drift, motion phases)")
      ->capture_default_str();
}

}  // namespace facedyn::app
