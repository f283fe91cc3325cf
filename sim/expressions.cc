#include "sim/expressions.h"

#include "physics/twin.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

#include "physics/face_anatomy.h"
#include "physics/twin.h"
#include "sim/procedural_face.h"

namespace facedyn::sim {
namespace {

using Combination = std::vector<std::pair<const char*, double>>;

// ARKit (ICT-FaceKit) combinations for the paper's expressions.
const std::map<std::string, Combination>& IctCombinations() {
  static const std::map<std::string, Combination> kCombinations = {
      {"smile",
       {{"mouthSmile_L", 1.0},
        {"mouthSmile_R", 1.0},
        {"cheekSquint_L", 0.4},
        {"cheekSquint_R", 0.4}}},
      {"jaw_open", {{"jawOpen", 1.0}}},
      {"pucker", {{"mouthPucker", 1.0}}},
      {"brow_raise",
       {{"browInnerUp_L", 1.0},
        {"browInnerUp_R", 1.0},
        {"browOuterUp_L", 1.0},
        {"browOuterUp_R", 1.0}}},
      {"squeeze",
       {{"eyeSquint_L", 1.0},
        {"eyeSquint_R", 1.0},
        {"eyeBlink_L", 0.6},
        {"eyeBlink_R", 0.6},
        {"browDown_L", 1.0},
        {"browDown_R", 1.0},
        {"noseSneer_L", 0.5},
        {"noseSneer_R", 0.5},
        {"cheekSquint_L", 0.5},
        {"cheekSquint_R", 0.5}}},
      {"cheek_puff", {{"cheekPuff_L", 1.0}, {"cheekPuff_R", 1.0}}},
      {"lip_funnel", {{"mouthFunnel", 1.0}}},
      {"mouth_stretch", {{"mouthStretch_L", 1.0}, {"mouthStretch_R", 1.0}}},
      {"sneer",
       {{"noseSneer_L", 1.0},
        {"noseSneer_R", 1.0},
        {"mouthUpperUp_L", 0.6},
        {"mouthUpperUp_R", 0.6}}},
      {"lips_parted",
       {{"jawOpen", 0.12},
        {"mouthLowerDown_L", 0.25},
        {"mouthLowerDown_R", 0.25},
        {"mouthUpperUp_L", 0.1},
        {"mouthUpperUp_R", 0.1}}},
  };
  return kCombinations;
}

std::string ValidNames(const FaceRig& rig) {
  std::string list;
  for (const auto& name : ExpressionNames()) list += (list.empty() ? "" : ", ") + name;
  for (const auto& name : rig.blendshape_names) list += ", " + name;
  return list;
}

}  // namespace

std::vector<std::string> ExpressionNames() {
  std::vector<std::string> names{"neutral"};
  for (const char* name : kProceduralExpressions) names.emplace_back(name);
  return names;
}

StatusOr<Eigen::VectorXd> ExpressionWeights(const FaceRig& rig, const std::string& name) {
  const Eigen::Index count = static_cast<Eigen::Index>(rig.blendshape_names.size());
  Eigen::VectorXd weights = Eigen::VectorXd::Zero(count);
  if (name == "neutral") return weights;
  const int direct = rig.BlendshapeIndex(name);
  if (direct >= 0) {
    weights[direct] = 1.0;
    return weights;
  }
  const auto combination = IctCombinations().find(name);
  if (combination != IctCombinations().end()) {
    for (const auto& [shape, weight] : combination->second) {
      const int k = rig.BlendshapeIndex(shape);
      if (k < 0) {
        return NotFoundError(fmt::format(
            "expression '{}': face rig '{}' has neither a blendshape '{}' nor the ARKit shape "
            "'{}' it is made of; valid names: {}",
            name, rig.name, name, shape, ValidNames(rig)));
      }
      weights[k] = weight;
    }
    return weights;
  }
  return NotFoundError(fmt::format("expression '{}' is unknown for face rig '{}'; valid names: {}",
                                   name, rig.name, ValidNames(rig)));
}

double JawOpenAngleRad(const FaceRig& rig) {
  if (rig.BlendshapeIndex("jaw_open") >= 0) return kProceduralJawOpenRad;
  return physics::FittedJawOpenAngleRad(rig);  // "jawOpen" (ICT), or 0
}

double JawAngleRad(const FaceRig& rig, const Eigen::VectorXd& weights) {
  FACEDYN_CHECK(weights.size() == static_cast<Eigen::Index>(rig.blendshape_names.size()),
                "JawAngleRad: one weight per blendshape");
  int k = rig.BlendshapeIndex("jaw_open");
  if (k < 0) k = rig.BlendshapeIndex("jawOpen");
  if (k < 0 || weights[k] == 0.0) return 0.0;
  return weights[k] * JawOpenAngleRad(rig);
}

StatusOr<std::vector<Eigen::VectorXd>> RangeOfMotionPoses(const FaceRig& rig) {
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::VectorXd jaw, ExpressionWeights(rig, "jaw_open"));
  std::vector<std::string> names = ExpressionNames();
  std::sort(names.begin(), names.end());
  std::vector<Eigen::VectorXd> poses;
  for (const std::string& name : names) {
    FACEDYN_ASSIGN_OR_RETURN(const Eigen::VectorXd w, ExpressionWeights(rig, name));
    poses.push_back(w);
    poses.push_back(0.5 * w);
    if (name != "neutral" && name != "jaw_open") poses.push_back((w + 0.5 * jaw).cwiseMin(1.0));
  }
  return poses;
}

StatusOr<std::vector<Eigen::VectorXd>> DialogueVisemes(const FaceRig& rig) {
  std::vector<Eigen::VectorXd> poses;
  for (const char* name :
       {"neutral", "lips_parted", "smile", "pucker", "lip_funnel", "mouth_stretch", "jaw_open"}) {
    FACEDYN_ASSIGN_OR_RETURN(Eigen::VectorXd w, ExpressionWeights(rig, name));
    if (std::string(name) == "jaw_open") w *= 0.4;
    poses.push_back(w);
  }
  return poses;
}

}  // namespace facedyn::sim
