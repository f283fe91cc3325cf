#include "dynamics/model_file.h"

#include <utility>

namespace facedyn::dynamics {

namespace {
constexpr char kPropagation[] = "propagation";
}  // namespace

Status SaveFeatureModel(const learn::Mlp& mlp, const FeatureSpec& spec, const std::string& kind,
                        int format_version, const SamplePropagation* propagation,
                        const std::string& path, const learn::MlpAttachments& extra) {
  Json json = spec.ToJson();
  json["format_version"] = format_version;
  learn::MlpAttachments attachments = extra;
  if (propagation != nullptr) {
    attachments[kPropagation] = propagation->weights();
    json["propagation_method"] = propagation->method();
  }
  return mlp.Save(path, kind, std::move(json), attachments);
}

StatusOr<learn::Mlp> LoadFeatureModel(const std::string& path, const std::string& kind,
                                      int format_version, FeatureSpec* spec,
                                      std::optional<SamplePropagation>* propagation,
                                      learn::MlpAttachments* extra) {
  Json json;
  learn::MlpAttachments attachments;
  FACEDYN_ASSIGN_OR_RETURN(learn::Mlp mlp, learn::Mlp::Load(path, kind, &json, &attachments));
  if (json.value("format_version", 0) != format_version) {
    return DataLossError(path + ": " + kind + " format_version " +
                         json.value("format_version", Json()).dump() +
                         " is not supported (expected " + std::to_string(format_version) + ")");
  }
  StatusOr<FeatureSpec> loaded = FeatureSpec::FromJson(json);
  if (!loaded.ok()) return loaded.status().WithContext(path);
  *spec = std::move(loaded).value();
  propagation->reset();
  if (auto found = attachments.find(kPropagation); found != attachments.end()) {
    if (found->second.cols() != spec->sample_count) {
      return DataLossError(path + ": propagation has " + std::to_string(found->second.cols()) +
                           " sample columns, the features " + std::to_string(spec->sample_count));
    }
    StatusOr<SamplePropagation> loaded_propagation = SamplePropagation::FromWeights(
        std::move(found->second), json.value("propagation_method", std::string("learned")));
    if (!loaded_propagation.ok()) return loaded_propagation.status().WithContext(path);
    *propagation = std::move(loaded_propagation).value();
    attachments.erase(found);
  }
  if (extra != nullptr) *extra = std::move(attachments);
  return mlp;
}

Status CheckNetworkSizes(const std::string& path, const learn::MlpShape& shape, int input_size,
                         int output_size) {
  if (shape.input_size != input_size || shape.output_size != output_size) {
    return DataLossError(path + ": network size " + std::to_string(shape.input_size) + " -> " +
                         std::to_string(shape.output_size) + " disagrees with its features (" +
                         std::to_string(input_size) + " -> " + std::to_string(output_size) + ")");
  }
  return Status::Ok();
}

}  // namespace facedyn::dynamics
