// The file layout both networks share (removal F, synthesis H): an learn::Mlp archive (mlp.h) whose
// JSON config is the model's FeatureSpec plus a per-kind "format_version", and, when the model
// has one, its learned propagation as the attachment "propagation" (V x S; propagation.h).
// Files without it (written before learned propagation) still load; the model then has none.
// A kind may keep more of its own matrices as further attachments (`extra`, e.g. H's
// "stretch_range"); files without them load with `extra` empty.
#pragma once

#include <optional>
#include <string>

#include "core/status.h"
#include "dynamics/feature_spec.h"
#include "learn/mlp.h"
#include "dynamics/propagation.h"

namespace facedyn::dynamics {

// `propagation` may be null (none saved).
Status SaveFeatureModel(const learn::Mlp& mlp, const FeatureSpec& spec, const std::string& kind,
                        int format_version, const SamplePropagation* propagation,
                        const std::string& path, const learn::MlpAttachments& extra = {});

// The network, its FeatureSpec and its propagation if saved; DataLoss (starting with the path)
// for another kind, another format_version, a bad spec, or a propagation whose column count is
// not the spec's sample count (its row count is checked against the rig when applied).
// `extra` (optional) receives the attachments other than the propagation.
StatusOr<learn::Mlp> LoadFeatureModel(const std::string& path, const std::string& kind,
                                      int format_version, FeatureSpec* spec,
                                      std::optional<SamplePropagation>* propagation,
                                      learn::MlpAttachments* extra = nullptr);

// DataLoss naming both sizes when the loaded network is not input_size -> output_size.
Status CheckNetworkSizes(const std::string& path, const learn::MlpShape& shape, int input_size,
                         int output_size);

}  // namespace facedyn::dynamics
