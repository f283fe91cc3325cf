// Face anatomy shared by every FaceRig generator (procedural and ICT-FaceKit import): named
// regions from a few facial landmarks, the soft-tissue thickness map, the skull surface under
// the skin, the skull landmarks b1..b5 (Zoss et al. 2020, Fig. 4a), the skin samples (Fig. 4b:
// 344 points) and the painted-marker layout.
//
// Why it is shaped this way: a generator only has to produce a skin mesh in the skull frame
// (mm, +Y up, face toward +Z, origin near the centre of the head) with named regions; the
// rest is derived here from geometry alone, so a procedural face and an imported scan get
// the same anatomy by the same rules and a rig can be regenerated bit for bit from its seed.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/face_rig.h"
#include "core/mesh.h"
#include "core/status.h"

namespace facedyn::physics {

// Where the features of a face are, in the skull frame (mm). X is the subject's left (+X),
// Y up, Z toward the viewer. Generators measure these on their mesh and pass them to
// LabelFaceRegions.
struct FaceLayout {
  double eye_center_x_mm = 32.0;      // |X| of each eye opening's centre
  double eye_center_y_mm = 15.0;      // Y of the eye openings' centres
  double eye_half_width_mm = 12.5;    // half the width of an eye opening
  double eye_half_height_mm = 4.5;    // half the height of an eye opening
  double brow_y_mm = 32.0;            // Y of the brow ridge
  double nose_tip_y_mm = -25.0;       // Y of the nose tip (pronasale)
  double nose_half_width_mm = 17.0;   // half the width of the nose at the alae
  double mouth_y_mm = -52.0;          // Y of the mouth opening (the line between the lips)
  double mouth_half_width_mm = 24.0;  // |X| of the mouth corners
  double chin_y_mm = -95.0;           // Y of the lowest point of the chin's front
  double temple_max_x_mm = 72.0;      // |X| beyond which nothing is labelled (ears, sides)
};

// Named vertex regions of a face mesh (names: forehead, brows, nose_bridge, temples, nose,
// cheeks, mouth_corners, lips, upper_lip, lower_lip, chin, eyes, jaw), from the rest positions
// (3 x V, skull frame), unit vertex normals (3 x V) and the layout. `jaw_weight` (size V, in
// [0, 1]) says how much each vertex follows the mandible; jaw = {w >= 0.5}, and it splits the
// lips into upper (w < 0.5) and lower (w >= 0.5). The primary regions (all but lips and jaw)
// are disjoint; lips = upper_lip + lower_lip. Vertices farther than temple_max_x_mm from the
// midline (ears, the back of a scan) get no region.
std::map<std::string, std::vector<int>> LabelFaceRegions(const Eigen::Matrix3Xd& positions_mm,
                                                         const Eigen::Matrix3Xd& normals,
                                                         const FaceLayout& layout,
                                                         const Eigen::VectorXd& jaw_weight);

// Vertices that move rigidly with the mandible, for fitting its hinge: jaw AND (chin OR cheeks)
// (lips and the soft neck are left out), or all of jaw when that is empty.
std::vector<int> JawFitVertices(const FaceRig& rig);


// Vertex adjacency (sorted neighbour lists) from the mesh's polygon edges.
std::vector<std::vector<int>> VertexNeighbors(const Mesh& mesh);

// True for every vertex on a boundary edge (an edge used by a single face): the rims of the
// eye and mouth openings and the outer edge of the mesh.
std::vector<bool> BoundaryVertices(const Mesh& mesh);

// Closed boundary loops of the mesh (vertex cycles along edges used by one face).
std::vector<std::vector<int>> BoundaryLoops(const Mesh& mesh);

// Soft-tissue thickness (mm) range per region, the clinical figures the thickness map obeys.
struct ThicknessRange {
  double min_mm;
  double target_mm;
  double max_mm;
};
// forehead 4-6, brows 4-7, nose_bridge 3-5, nose 2-4, temples 5-8, eyes 4-7, cheeks 12-20,
// mouth_corners 10-16, upper_lip / lower_lip 10-14, chin 8-12. Vertices in no region start at
// kDefaultThicknessMm and blend freely.
const std::map<std::string, ThicknessRange>& RegionThicknessRanges();
inline constexpr double kDefaultThicknessMm = 7.0;
// Width of the band on each side of a region border where thickness blends between regions.
inline constexpr double kThicknessBlendMm = 5.0;

// Distance (mm, along mesh edges) from each vertex to the border of its thickness region (the
// nearest edge to a vertex of another region or of none); 0 on the border.
std::vector<double> ThicknessBorderDistanceMm(const FaceRig& rig);

// Per-vertex soft-tissue thickness (mm, size V): each region's target value, then diffused over
// the mesh (about 15 mm) with every vertex farther than kThicknessBlendMm inside its region held
// inside the region's range: smooth across region borders, clinical inside regions.
// Depends only on rig.neutral and rig.regions (recomputable at any time).
Eigen::VectorXd TissueThicknessMm(const FaceRig& rig);

struct AnatomyOptions {
  int skin_sample_count = 344;  // Zoss et al. 2020, Fig. 4b
  int marker_count = 150;       // painted dots for reconstruction
  double marker_diameter_mm = 2.0;
  uint64_t seed = 1;  // picks the first sample of each farthest-point sampling
  Status Check() const;
};

// Fills rig->skull, skull_landmarks, skin_samples, markers and stable_regions from
// rig->neutral and rig->regions (which must contain forehead, nose_bridge and temples).
//
// The skull surface has THE SAME TOPOLOGY AND VERTEX COUNT as the neutral skin: skull vertex i
// lies under skin vertex i, at skin_i - t_i n_i with t = TissueThicknessMm(*rig) and n the
// vertex normals of the skin smoothed over a few rings (so the inner surface does not fold
// under the lips and nose). The soft-tissue physics relies on that one-to-one pairing.
// Landmarks (skull frame, on the cranium, not on the skin mesh): b1 forehead (top of the
// frontal bone), b2 left temple, b3 right temple, b4 nasion (root of the nose bridge),
// b5 crown (top-back of the head, on the sphere through b1 about the origin).
// Skin samples and markers: farthest-point sampling (Euclidean distance) over the vertices off
// the hole and outer boundaries (markers: front-facing, outside the eye region), starting at a
// vertex chosen by `seed`; deterministic.
Status CompleteFaceAnatomy(const AnatomyOptions& options, FaceRig* rig);

// Least-squares hinge angle (rad, right-handed about `axis`, unit) of the rotation about the
// line through `pivot_mm` along `axis` that best moves `points_mm` (3 x N) by `deltas_mm`
// (3 x N): the 2D Procrustes angle in the plane normal to the axis. Exact for a rigid rotation
// about that hinge.
double FitHingeAngleRad(const Eigen::Matrix3Xd& points_mm, const Eigen::Matrix3Xd& deltas_mm,
                        const Eigen::Vector3d& axis, const Eigen::Vector3d& pivot_mm);

// Farthest-point sampling of `count` points among `candidates` (vertex indices) of
// `positions_mm`, first point candidates[seed % size]. Returns vertex indices in pick order.
// Precondition: count <= candidates.size().
std::vector<int> FarthestPointSample(const Eigen::Matrix3Xd& positions_mm,
                                     const std::vector<int>& candidates, int count, uint64_t seed);

}  // namespace facedyn::physics
