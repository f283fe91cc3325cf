// The named expressions of Zoss et al. 2020 (neutral plus ten held expressions) for any FaceRig,
// as blendshape weight vectors, and the mandible rotation a weight vector implies.
//
// A procedural rig has one blendshape per expression (same names); an ICT-FaceKit rig has the
// 53 ARKit-style shapes, and each expression is a fixed combination of them (FACS
// correspondences of the ICT README: AU12 lip corner puller = mouthSmile_L + mouthSmile_R, ...).
// Every weight lies in [0, 1]. Any blendshape name of the rig is accepted too (weight 1).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/status.h"

namespace facedyn::sim {

// "neutral", then smile, jaw_open, pucker, brow_raise, squeeze, cheek_puff, lip_funnel,
// mouth_stretch, sneer, lips_parted.
std::vector<std::string> ExpressionNames();

// Blendshape weights (size = rig.blendshape_names.size(), each in [0, 1]) of the expression
// `name`: an ExpressionNames() entry or any blendshape name of the rig. Unknown names, or a
// named expression the rig's shapes cannot form, give kNotFound listing the valid names.
StatusOr<Eigen::VectorXd> ExpressionWeights(const FaceRig& rig, const std::string& name);

// Key poses of a range-of-motion performance (what Masquerade trains on, Moser et al. 2017):
// every ExpressionNames() entry, in name order, at full and half weight, and each one but neutral
// and jaw_open with the jaw half open (clamped to 1). Errors: the rig cannot form an expression.
StatusOr<std::vector<Eigen::VectorXd>> RangeOfMotionPoses(const FaceRig& rig);

// Key poses of a dialogue (the visemes sim/performance.cc's "speech" moves through): neutral,
// lips_parted, smile, pucker, lip_funnel, mouth_stretch and jaw_open at 0.4.
StatusOr<std::vector<Eigen::VectorXd>> DialogueVisemes(const FaceRig& rig);

// Mandible rotation (rad, about rig.jaw.axis_in_skull through its pivot; positive opens) of the
// jaw-opening shape at weight 1: kProceduralJawOpenRad for a procedural rig ("jaw_open"); for
// an ICT rig ("jawOpen") the rotation about the rig's hinge fitted by least squares to that
// shape's deltas over physics::JawFitVertices (chin and lower cheeks). 0 when the rig has neither.
double JawOpenAngleRad(const FaceRig& rig);

// Mandible rotation implied by `weights` (precondition: one weight per blendshape): the jaw
// shape's weight times JawOpenAngleRad(rig).
double JawAngleRad(const FaceRig& rig, const Eigen::VectorXd& weights);

}  // namespace facedyn::sim
