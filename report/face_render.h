// Renders of a face coloured by signed dynamic offset, as in Zoss et al. 2020's figures (red out
// of the skin, green into it, saturating at +-range_mm; grey where there is none), for the demo
// report. facedyn draws them itself: an orthographic view of the skull frame from the front
// (+Z, the direction the face looks), triangles filled far to near (painter's algorithm, exact
// for the single-layer face surface seen from the front except at self-occluding folds), with
// Lambert shading so the shape reads under the colour.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace facedyn::report {

struct OffsetRenderOptions {
  int width_px = 360;
  int height_px = 440;
  double range_mm = 5.0;  // colour saturates at +-range
};

// PNG bytes of the surface `positions_in_skull` (3 x V, mm) with per-vertex offsets
// (3 x V, skull frame, mm) projected on the outward vertex normal. Preconditions: sizes match
// the topology, which has faces.
std::vector<unsigned char> RenderSignedOffsetPng(const Mesh& topology,
                                                 const Eigen::Matrix3Xf& positions_in_skull,
                                                 const Eigen::Matrix3Xf& offsets_in_skull,
                                                 const OffsetRenderOptions& options = {});

// RFC 4648 base64 (for data: URIs in the self-contained report).
std::string Base64(const std::vector<unsigned char>& bytes);

}  // namespace facedyn::report
