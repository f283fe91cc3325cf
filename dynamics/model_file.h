// The file layout both networks share (removal F, synthesis H): an Mlp archive (mlp.h) whose
// JSON config is the model's FeatureSpec plus a per-kind "format_version".
#pragma once

#include <string>

#include "core/status.h"
#include "dynamics/feature_spec.h"
#include "dynamics/mlp.h"

namespace facedyn::dynamics {

Status SaveFeatureModel(const Mlp& mlp, const FeatureSpec& spec, const std::string& kind,
                        int format_version, const std::string& path);

// The network and its FeatureSpec; DataLoss (starting with the path) for another kind, another
// format_version or a bad spec.
StatusOr<Mlp> LoadFeatureModel(const std::string& path, const std::string& kind, int format_version,
                               FeatureSpec* spec);

// DataLoss naming both sizes when the loaded network is not input_size -> output_size.
Status CheckNetworkSizes(const std::string& path, const MlpShape& shape, int input_size,
                         int output_size);

}  // namespace facedyn::dynamics
