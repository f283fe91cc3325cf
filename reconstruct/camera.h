// The camera model reconstruction uses is capture's (capture/camera_model.h): pinhole plus
// OpenCV's 5-coefficient distortion, cam_from_world, image size. These aliases keep
// reconstruct's code short.
#pragma once

#include "capture/camera_model.h"

namespace facedyn::reconstruct {

using Camera = capture::CameraModel;
using capture::DistortAndScale;
using capture::Intrinsics;
using capture::kIntrinsicCount;

}  // namespace facedyn::reconstruct
