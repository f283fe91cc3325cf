// Region and channel tables of an FDLS solver (FDLS section 4.4 and supplementary section 9),
// per rig, from YAML (config/solve/<rig>.yaml) or the embedded default of the procedural face.
//
//   rig: procedural                 # informative; the tables are checked against the puppet
//   always_include: [nose_bridge]   # FDLS 4.4: a nose-bridge marker joins every region
//   max_markers_per_region: 16      # farthest-point subset beyond this (features grow as n^2)
//   jaw:                            # solved first, from the jaw-region markers (4.4.1)
//     rig_regions: [jaw, chin]      # FaceRig regions whose markers the network sees
//     channels: [jaw_open]
//     features: direction+delta
//   regions:                        # then one network per region, conditioned on the jaw
//     - name: mouth
//       rig_regions: [lips, mouth_corners]
//       channels: [smile, pucker]
//       features: distance+direction+delta
//       jaw_conditioned: true
//   network: {hidden_units: 128, residual_blocks: 2, dropout: 0.01, epochs: 60,
//             batch_size: 64, learning_rate: 1e-3, weight_decay: 1e-5}
//
// Every channel of the puppet belongs to exactly one region (the jaw counts as one); a channel
// the rig does not have, a region name the rig does not have, or a channel left out is an error
// naming it.
#pragma once

#include <string>
#include <vector>

#include "core/config_node.h"
#include "core/face_rig.h"
#include "core/status.h"
#include "solve/features.h"
#include "solve/puppet.h"

namespace facedyn::solve {

struct RegionSpec {
  std::string name;
  std::vector<std::string> rig_regions;
  std::vector<std::string> channels;
  FeatureSet features;
  bool jaw_conditioned = false;
};

struct NetworkSpec {
  int hidden_units = 128;
  int residual_blocks = 2;  // hidden layers after the first, each residual (FDLS Fig. 4)
  double dropout = 0.01;    // supplementary table: 0.01 for most regions
  int epochs = 60;
  int batch_size = 64;  // supplementary table
  double learning_rate = 1e-3;
  double weight_decay = 1e-5;  // the table's l2, as decoupled decay
};

struct SolveConfig {
  std::string rig;
  std::vector<std::string> always_include{"nose_bridge"};
  int max_markers_per_region = 16;
  RegionSpec jaw;  // name "jaw"
  std::vector<RegionSpec> regions;
  NetworkSpec network;
};

// Parses a document (errors name the file, line and field).
StatusOr<SolveConfig> ParseSolveConfig(const ConfigNode& root);
StatusOr<SolveConfig> ReadSolveConfig(const std::string& path);
// The tables for the procedural face (the same text as config/solve/procedural.yaml).
const char* ProceduralSolveConfigYaml();
StatusOr<SolveConfig> ProceduralSolveConfig();

// A region bound to a puppet: marker and channel indices.
struct ResolvedRegion {
  RegionSpec spec;
  std::vector<int> markers;   // puppet marker indices, ascending
  std::vector<int> channels;  // puppet channel indices, in the spec's order
};

struct ResolvedConfig {
  ResolvedRegion jaw;
  std::vector<ResolvedRegion> regions;
  NetworkSpec network;
};

// Binds the tables to a rig's puppet: markers by the rig regions their vertex lies in (plus the
// always_include marker nearest its region's centroid), subset to max_markers_per_region by
// farthest-point sampling. Errors name unknown channels and regions, channels in two regions or
// in none, and regions left with fewer than two markers.
StatusOr<ResolvedConfig> ResolveSolveConfig(const SolveConfig& config, const FaceRig& rig,
                                            const Puppet& puppet);

}  // namespace facedyn::solve
