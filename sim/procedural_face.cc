#include "sim/procedural_face.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace facedyn::sim {
namespace {

// Extent of the face and its features in the (u, y) parameter plane (mm).
constexpr double kYBottomMm = -112.0;
constexpr double kYTopMm = 95.0;
constexpr double kMaxAzimuthRad = 1.45;   // the sheet wraps to ~83 degrees each side
constexpr double kRefHalfWidthMm = 72.0;  // reference ellipse for the arc-length u
constexpr double kRefDepthMm = 92.0;
constexpr double kEyeU = 33.0, kEyeY = 15.0, kEyeHalfWidth = 12.5, kEyeHalfHeight = 4.5;
constexpr double kMouthY = -52.0, kMouthHalfWidth = 24.0;
constexpr double kBrowY = 31.0, kNoseTipY = -25.0, kChinY = -95.0;

double Gauss(double x) { return std::exp(-x * x); }
double Gauss2(double u, double y, double cu, double cy, double su, double sy) {
  return Gauss((u - cu) / su) * Gauss((y - cy) / sy);
}
// 0 at x <= e0, 1 at x >= e1 (either order of edges), C1 in between.
double SmoothStep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}
double Sign(double x) { return x > 0 ? 1.0 : (x < 0 ? -1.0 : 0.0); }

// Catmull-Rom interpolation of a profile given at increasing knots.
double Profile(const std::vector<std::array<double, 2>>& knots, double y) {
  const int n = static_cast<int>(knots.size());
  if (y <= knots.front()[0]) return knots.front()[1];
  if (y >= knots.back()[0]) return knots.back()[1];
  int k = 0;
  while (k + 2 < n && y > knots[k + 1][0]) ++k;
  const double y0 = knots[k][0], y1 = knots[k + 1][0];
  const double t = (y - y0) / (y1 - y0);
  const double p0 = knots[std::max(k - 1, 0)][1], p1 = knots[k][1], p2 = knots[k + 1][1],
               p3 = knots[std::min(k + 2, n - 1)][1];
  const double m1 = 0.5 * (p2 - p0), m2 = 0.5 * (p3 - p1);
  const double t2 = t * t, t3 = t2 * t;
  return (2 * t3 - 3 * t2 + 1) * p1 + (t3 - 2 * t2 + t) * m1 + (-2 * t3 + 3 * t2) * p2 +
         (t3 - t2) * m2;
}

double HalfWidthMm(double y) {
  static const std::vector<std::array<double, 2>> kKnots = {
      {-115, 25}, {-100, 35}, {-80, 50}, {-55, 60}, {-30, 68},
      {-5, 73},   {15, 74},   {40, 72},  {70, 68},  {100, 60}};
  return Profile(kKnots, y);
}
double DepthMm(double y) {
  static const std::vector<std::array<double, 2>> kKnots = {
      {-115, 62}, {-100, 80}, {-85, 86}, {-55, 90}, {-25, 94},
      {0, 95},    {20, 94},   {45, 92},  {70, 86},  {100, 74}};
  return Profile(kKnots, y);
}

// Arc length u(theta) on the reference ellipse, tabulated for inversion.
class ArcLength {
 public:
  ArcLength() {
    constexpr int kSteps = 4000;
    theta_.resize(kSteps + 1);
    arc_.resize(kSteps + 1);
    arc_[0] = 0.0;
    for (int i = 0; i <= kSteps; ++i) {
      theta_[i] = kMaxAzimuthRad * i / kSteps;
      if (i == 0) continue;
      const double mid = 0.5 * (theta_[i] + theta_[i - 1]);
      const double speed = std::hypot(kRefHalfWidthMm * std::cos(mid), kRefDepthMm * std::sin(mid));
      arc_[i] = arc_[i - 1] + speed * (theta_[i] - theta_[i - 1]);
    }
  }
  double max_arc_mm() const { return arc_.back(); }
  double Theta(double u) const {
    const double a = std::min(std::abs(u), arc_.back());
    const auto it = std::lower_bound(arc_.begin(), arc_.end(), a);
    const size_t i = std::clamp<size_t>(it - arc_.begin(), 1, arc_.size() - 1);
    const double t = (a - arc_[i - 1]) / (arc_[i] - arc_[i - 1]);
    return Sign(u) * (theta_[i - 1] + t * (theta_[i] - theta_[i - 1]));
  }

 private:
  std::vector<double> theta_, arc_;
};

// Height of the face's features above the base surface, along its normal (mm).
double FeatureOffsetMm(double u, double y) {
  const double au = std::abs(u);
  double d = 0.0;
  d += -6.0 * Gauss2(au, y, kEyeU, kEyeY - 1.0, 15.0, 11.0);         // eye sockets
  d += 3.0 * Gauss2(au, y, kEyeU, kEyeY, 12.0, 7.0);                 // eyelids over the eyeball
  d += 4.5 * Gauss((y - kBrowY) / 7.0) * Gauss((au - 22.0) / 28.0);  // brow ridge
  d += -2.0 * Gauss2(u, y, 0.0, 20.0, 8.0, 6.0);                     // nasion
  // Nose: rises from the bridge to the tip, falls off under it; widens toward the tip.
  const double t = std::clamp((26.0 - y) / (26.0 - kNoseTipY), 0.0, 1.0);
  const double rise = t * (1.4 - 0.4 * t) * SmoothStep(0.0, 0.15, t);
  const double fall = 1.0 - SmoothStep(kNoseTipY, kNoseTipY - 11.0, y);
  d += 19.0 * rise * fall * Gauss(u / (5.5 + 5.0 * t));
  d += 2.0 * Gauss2(u, y, 0.0, kNoseTipY + 1.0, 6.0, 5.0);    // rounded tip
  d += 5.0 * Gauss2(au, y, 13.0, kNoseTipY - 3.0, 5.5, 6.0);  // alae
  d += 5.0 * Gauss2(au, y, 45.0, -2.0, 18.0, 14.0);           // cheekbones
  d += 7.0 * Gauss2(u, y, 0.0, kMouthY - 3.0, 34.0, 26.0);    // muzzle over the teeth
  const double lip_w = std::exp(-std::pow(u / (kMouthHalfWidth + 2.0), 4));
  d += 3.5 * lip_w * Gauss((y - (kMouthY + 5.0)) / 4.0);     // upper lip
  d += 4.0 * lip_w * Gauss((y - (kMouthY - 6.0)) / 4.5);     // lower lip
  d += -3.0 * lip_w * Gauss((y - kMouthY) / 2.2);            // lips roll in at the slit
  d += -2.5 * Gauss2(u, y, 0.0, kMouthY - 17.0, 20.0, 5.0);  // mentolabial sulcus
  d += 6.0 * Gauss2(u, y, 0.0, kChinY + 3.0, 16.0, 10.0);    // chin
  return d;
}

struct SurfaceFrame {
  Eigen::Vector3d position;
  Eigen::Vector3d normal;  // of the base surface, horizontal
};

SurfaceFrame Evaluate(const ArcLength& arc, double u, double y) {
  const double theta = arc.Theta(u);
  const double a = HalfWidthMm(y), c = DepthMm(y);
  const Eigen::Vector3d base(a * std::sin(theta), y, c * std::cos(theta));
  const Eigen::Vector3d normal =
      Eigen::Vector3d(std::sin(theta) / a, 0.0, std::cos(theta) / c).normalized();
  return {base + FeatureOffsetMm(u, y) * normal, normal};
}

// How much a point follows the mandible: 1 below the mouth slit and along the jaw line,
// 0 above; a sharp step across the slit (the lips separate), a ~20 mm blend on the cheeks.
double JawWeight(double u, double y, double cell_mm) {
  const double au = std::abs(u);
  const double line = kMouthY + 0.55 * std::max(0.0, au - kMouthHalfWidth);
  const double width =
      0.5 * cell_mm + 10.0 * SmoothStep(kMouthHalfWidth - 2.0, kMouthHalfWidth + 25.0, au);
  return 1.0 - SmoothStep(-width, width, y - line);
}

struct Grid {
  int columns = 0, rows = 0;  // cells
  double u0 = 0, du = 0, y0 = 0, dy = 0;
  std::vector<char> cell_hole;  // 0 kept, 1 eye, 2 mouth; columns * rows
  int Vertex(int i, int j) const { return j * (columns + 1) + i; }
};

Grid MakeGrid(const ArcLength& arc, double cell_mm) {
  Grid g;
  const double width = 2.0 * arc.max_arc_mm();
  g.columns = std::max(8, static_cast<int>(std::lround(width / cell_mm)));
  g.du = width / g.columns;
  g.u0 = -arc.max_arc_mm();
  g.dy = cell_mm;
  // A row of cell centres lies exactly on the mouth line, so the slit is one row high.
  const int below = static_cast<int>(std::lround((kMouthY - kYBottomMm) / cell_mm - 0.5));
  g.y0 = kMouthY - (below + 0.5) * cell_mm;
  g.rows = static_cast<int>(std::lround((kYTopMm - g.y0) / cell_mm));
  g.cell_hole.assign(static_cast<size_t>(g.columns) * g.rows, 0);
  for (int j = 0; j < g.rows; ++j) {
    for (int i = 0; i < g.columns; ++i) {
      const double u = g.u0 + (i + 0.5) * g.du, y = g.y0 + (j + 0.5) * g.dy;
      const double eu = (std::abs(u) - kEyeU) / kEyeHalfWidth, ev = (y - kEyeY) / kEyeHalfHeight;
      char& hole = g.cell_hole[static_cast<size_t>(j) * g.columns + i];
      if (eu * eu + ev * ev < 1.0) hole = 1;
      if (std::abs(y - kMouthY) < 0.3 * g.dy && std::abs(u) < kMouthHalfWidth - 0.5 * g.du)
        hole = 2;
    }
  }
  return g;
}

// Vertices used by at least one kept cell.
std::vector<bool> UsedVertices(const Grid& g) {
  std::vector<bool> used(static_cast<size_t>(g.columns + 1) * (g.rows + 1), false);
  for (int j = 0; j < g.rows; ++j) {
    for (int i = 0; i < g.columns; ++i) {
      if (g.cell_hole[static_cast<size_t>(j) * g.columns + i]) continue;
      used[g.Vertex(i, j)] = used[g.Vertex(i + 1, j)] = used[g.Vertex(i, j + 1)] =
          used[g.Vertex(i + 1, j + 1)] = true;
    }
  }
  return used;
}

int CountUsed(const Grid& g) {
  const auto used = UsedVertices(g);
  return static_cast<int>(std::count(used.begin(), used.end(), true));
}

Eigen::Vector3d RotateAboutX(const Eigen::Vector3d& p, const Eigen::Vector3d& pivot,
                             double angle_rad) {
  return pivot + Eigen::AngleAxisd(angle_rad, Eigen::Vector3d::UnitX()) * (p - pivot);
}

// The expression's displacement (mm) of a rest point at parameters (u, y) with base normal n.
Eigen::Vector3d ExpressionDelta(int expression, double u, double y, const Eigen::Vector3d& p,
                                const Eigen::Vector3d& n, double jaw_weight) {
  const double s = Sign(u), au = std::abs(u);
  const double lips = Gauss2(u, y, 0.0, kMouthY, kMouthHalfWidth - 2.0, 12.0);
  const double corner = Gauss2(au, y, kMouthHalfWidth, kMouthY, 13.0, 11.0);
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  switch (expression) {
    case 0: {  // smile: corners up and back, cheeks bulge up and out, lower lids lift
      d += corner * Eigen::Vector3d(s * 2.5, 7.0, -5.0);
      const double cheek = Gauss2(au, y, 40.0, -22.0, 16.0, 14.0);
      d += cheek * (Eigen::Vector3d(s * 1.0, 3.0, 0.0) + 4.0 * n);
      d.x() += 0.12 * u * Gauss((y - kMouthY) / 10.0) * Gauss(u / 40.0);
      d.y() += 1.5 * Gauss2(au, y, kEyeU, kEyeY - 10.0, 14.0, 5.0);
      break;
    }
    case 1:  // jaw_open: the mandible's rotation, blended by the jaw weight
      d = jaw_weight * (RotateAboutX(p, kProceduralJawPivotMm, kProceduralJawOpenRad) - p);
      break;
    case 2:  // pucker: lips forward and gathered toward the middle
      d += lips * Eigen::Vector3d(-0.3 * u, 0.0, 9.0);
      d += corner * Eigen::Vector3d(-s * 4.0, 0.0, 3.0);
      break;
    case 3: {  // brow_raise: brows up, the forehead follows less, lids a little
      const double across = Gauss((au - 20.0) / 35.0);
      const double along = y < kBrowY ? Gauss((y - kBrowY) / 11.0) : Gauss((y - kBrowY) / 25.0);
      d += 8.0 * across * along * Eigen::Vector3d(0.0, 1.0, 0.12);
      break;
    }
    case 4:  // squeeze: brows down and in, lids close, cheeks up, nose wrinkles
      d += Gauss((au - 25.0) / 25.0) * Gauss((y - 30.0) / 10.0) *
           Eigen::Vector3d(-s * 2.0, -5.0, 1.0);
      d += Gauss2(au, y, kEyeU, kEyeY + 4.5, 12.0, 3.5) * Eigen::Vector3d(0.0, -3.5, 0.5);
      d += Gauss2(au, y, kEyeU, kEyeY - 4.0, 12.0, 3.0) * Eigen::Vector3d(0.0, 2.0, 0.5);
      d += Gauss2(au, y, 38.0, -5.0, 18.0, 12.0) * Eigen::Vector3d(0.0, 4.0, 1.5);
      d += Gauss2(u, y, 0.0, 5.0, 8.0, 8.0) * Eigen::Vector3d(0.0, 2.0, 0.0);
      break;
    case 5:  // cheek_puff: cheeks blown out along the normal, lips pushed a little forward
      d += 8.0 * Gauss2(au, y, 45.0, -40.0, 20.0, 18.0) * n;
      d += 1.5 * lips * Eigen::Vector3d::UnitZ();
      break;
    case 6: {  // lip_funnel: lips forward and flared open
      const double lip_w = std::exp(-std::pow(u / (kMouthHalfWidth + 2.0), 4));
      d += lips * Eigen::Vector3d(-0.15 * u, 0.0, 6.0);
      d.y() += 2.5 * lip_w * Gauss((y - (kMouthY + 4.0)) / 5.0);
      d.y() -= 2.5 * lip_w * Gauss((y - (kMouthY - 5.0)) / 5.0);
      break;
    }
    case 7:  // mouth_stretch: corners out and down, lips thin
      d += corner * Eigen::Vector3d(s * 7.0, -3.0, -2.0);
      d.y() += (y >= kMouthY ? -1.0 : 1.0) * Gauss2(u, y, 0.0, kMouthY, kMouthHalfWidth, 7.0);
      break;
    case 8:  // sneer: upper lip and alae up, nasolabial folds deepen
      d += Gauss2(au, y, 12.0, kMouthY + 6.0, 10.0, 8.0) * Eigen::Vector3d(0.0, 5.0, 1.0);
      d += Gauss2(au, y, 13.0, kNoseTipY, 7.0, 8.0) * Eigen::Vector3d(0.0, 4.0, 0.5);
      d += Gauss2(au, y, 25.0, -30.0, 8.0, 10.0) * Eigen::Vector3d(0.0, 2.0, 1.5);
      break;
    case 9:  // lips_parted: relaxed lips, lower lip drops ~3 mm, upper lifts ~1 mm
      d += jaw_weight * Gauss2(u, y, 0.0, kMouthY - 8.0, kMouthHalfWidth + 8.0, 14.0) *
           Eigen::Vector3d(0.0, -3.0, 0.5);
      d += (1.0 - jaw_weight) * Gauss2(u, y, 0.0, kMouthY + 6.0, kMouthHalfWidth + 6.0, 10.0) *
           Eigen::Vector3d(0.0, 1.0, 0.0);
      break;
    default:
      break;
  }
  return d;
}

}  // namespace

Status ProceduralFaceOptions::Check() const {
  if (target_vertex_count < 4000 || target_vertex_count > 10000) {
    return InvalidArgumentError(
        fmt::format("target_vertex_count: {} is outside 4000..10000", target_vertex_count));
  }
  if (name.empty()) return InvalidArgumentError("name: must not be empty");
  return anatomy.Check();
}

StatusOr<FaceRig> MakeProceduralFace(const ProceduralFaceOptions& options) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  static const ArcLength arc;

  // Cell size: start from the area, then correct for the holes and rounding.
  double cell_mm =
      std::sqrt(2.0 * arc.max_arc_mm() * (kYTopMm - kYBottomMm) / options.target_vertex_count);
  Grid grid = MakeGrid(arc, cell_mm);
  for (int it = 0; it < 6; ++it) {
    const int count = CountUsed(grid);
    if (std::abs(count - options.target_vertex_count) < 0.015 * options.target_vertex_count) break;
    cell_mm *= std::sqrt(static_cast<double>(count) / options.target_vertex_count);
    grid = MakeGrid(arc, cell_mm);
  }

  // Kept vertices in row-major order.
  const std::vector<bool> used = UsedVertices(grid);
  std::vector<int> index(used.size(), -1);
  int vertex_count = 0;
  for (size_t k = 0; k < used.size(); ++k) {
    if (used[k]) index[k] = vertex_count++;
  }
  // Parameters per vertex; hole rims are then pulled toward the openings' outlines.
  Eigen::Matrix2Xd param(2, vertex_count), grid_param(2, vertex_count);
  std::vector<char> rim(vertex_count, 0);
  for (int j = 0; j <= grid.rows; ++j) {
    for (int i = 0; i <= grid.columns; ++i) {
      const int v = index[grid.Vertex(i, j)];
      if (v < 0) continue;
      grid_param.col(v) << grid.u0 + i * grid.du, grid.y0 + j * grid.dy;
      for (int dj = -1; dj <= 0; ++dj) {
        for (int di = -1; di <= 0; ++di) {
          const int ci = i + di, cj = j + dj;
          if (ci < 0 || cj < 0 || ci >= grid.columns || cj >= grid.rows) continue;
          rim[v] = std::max(rim[v], grid.cell_hole[static_cast<size_t>(cj) * grid.columns + ci]);
        }
      }
    }
  }
  param = grid_param;
  const double max_move = 0.4 * std::min(grid.du, grid.dy);
  for (int v = 0; v < vertex_count; ++v) {
    const double u = grid_param(0, v), y = grid_param(1, v);
    if (rim[v] == 1) {
      const Eigen::Vector2d center(Sign(u) * kEyeU, kEyeY);
      const Eigen::Vector2d p(u, y);
      const Eigen::Vector2d r = p - center;
      const double f = std::hypot(r.x() / kEyeHalfWidth, r.y() / kEyeHalfHeight);
      if (f > 1e-9) {
        Eigen::Vector2d move = center + r / f - p;
        if (move.norm() > max_move) move *= max_move / move.norm();
        param.col(v) += move;
      }
    } else if (rim[v] == 2) {
      const double half = kMouthHalfWidth;
      const double lens = std::max(0.25, std::sqrt(std::max(0.0, 1.0 - (u / half) * (u / half))));
      param(1, v) = kMouthY + (y - kMouthY) * lens;
    }
  }

  FaceRig rig;
  rig.name = options.name;
  Mesh& mesh = rig.neutral;
  mesh.positions_mm.resize(3, vertex_count);
  mesh.uvs.resize(2, vertex_count);
  Eigen::Matrix3Xd base_normals(3, vertex_count);
  const double u_span = grid.columns * grid.du, y_span = grid.rows * grid.dy;
  for (int v = 0; v < vertex_count; ++v) {
    const SurfaceFrame frame = Evaluate(arc, param(0, v), param(1, v));
    mesh.positions_mm.col(v) = frame.position;
    base_normals.col(v) = frame.normal;
    mesh.uvs.col(v) << (param(0, v) - grid.u0) / u_span, (param(1, v) - grid.y0) / y_span;
  }
  for (int j = 0; j < grid.rows; ++j) {
    for (int i = 0; i < grid.columns; ++i) {
      if (grid.cell_hole[static_cast<size_t>(j) * grid.columns + i]) continue;
      const int a = index[grid.Vertex(i, j)], b = index[grid.Vertex(i + 1, j)];
      const int c = index[grid.Vertex(i + 1, j + 1)], d = index[grid.Vertex(i, j + 1)];
      // Counter-clockwise in (u, y), i.e. seen from outside; diagonals mirrored about u = 0.
      if (grid.u0 + (i + 0.5) * grid.du >= 0.0) {
        mesh.AddFace({a, b, c}, {a, b, c});
        mesh.AddFace({a, c, d}, {a, c, d});
      } else {
        mesh.AddFace({a, b, d}, {a, b, d});
        mesh.AddFace({b, c, d}, {b, c, d});
      }
    }
  }

  Eigen::VectorXd jaw_weight(vertex_count);
  for (int v = 0; v < vertex_count; ++v)
    jaw_weight[v] = JawWeight(grid_param(0, v), grid_param(1, v), grid.dy);

  for (int k = 0; k < static_cast<int>(std::size(kProceduralExpressions)); ++k) {
    Eigen::Matrix3Xd delta(3, vertex_count);
    for (int v = 0; v < vertex_count; ++v) {
      delta.col(v) = ExpressionDelta(k, param(0, v), param(1, v), mesh.positions_mm.col(v),
                                     base_normals.col(v), jaw_weight[v]);
    }
    rig.blendshape_names.emplace_back(kProceduralExpressions[k]);
    rig.blendshape_deltas_mm.push_back(std::move(delta));
  }

  // Layout in 3D (X of a feature = its base-surface X).
  physics::FaceLayout layout;
  layout.eye_center_x_mm = HalfWidthMm(kEyeY) * std::sin(arc.Theta(kEyeU));
  layout.eye_center_y_mm = kEyeY;
  layout.eye_half_width_mm = kEyeHalfWidth;
  layout.eye_half_height_mm = kEyeHalfHeight;
  layout.brow_y_mm = kBrowY;
  layout.nose_tip_y_mm = kNoseTipY;
  layout.nose_half_width_mm = 17.0;
  layout.mouth_y_mm = kMouthY;
  layout.mouth_half_width_mm = HalfWidthMm(kMouthY) * std::sin(arc.Theta(kMouthHalfWidth));
  layout.chin_y_mm = kChinY;
  layout.temple_max_x_mm = 72.0;
  rig.regions = physics::LabelFaceRegions(mesh.positions_mm, VertexNormals(mesh, mesh.positions_mm),
                                          layout, jaw_weight);
  rig.jaw.pivot_in_skull = kProceduralJawPivotMm;
  rig.jaw.axis_in_skull = Eigen::Vector3d::UnitX();
  rig.jaw.region = "jaw";

  FACEDYN_RETURN_IF_ERROR(physics::CompleteFaceAnatomy(options.anatomy, &rig));
  FACEDYN_RETURN_IF_ERROR(rig.Validate());
  return rig;
}

StatusOr<FaceRig> ScaledFaceRig(const FaceRig& rig, const Eigen::Vector3d& scale,
                                const std::string& name) {
  if (!(scale.array() > 0).all() || !scale.allFinite()) {
    return InvalidArgumentError(fmt::format("ScaledFaceRig: scale ({}, {}, {}) must be > 0",
                                            scale.x(), scale.y(), scale.z()));
  }
  FaceRig scaled = rig;
  scaled.name = name;
  const Eigen::DiagonalMatrix<double, 3> s(scale);
  scaled.neutral.positions_mm = s * rig.neutral.positions_mm;
  scaled.skull.positions_mm = s * rig.skull.positions_mm;
  for (Eigen::Matrix3Xd& delta : scaled.blendshape_deltas_mm) delta = s * delta;
  for (SkullLandmark& landmark : scaled.skull_landmarks) {
    landmark.position_in_skull = s * landmark.position_in_skull;
  }
  scaled.jaw.pivot_in_skull = s * rig.jaw.pivot_in_skull;
  FACEDYN_RETURN_IF_ERROR(scaled.Validate());
  return scaled;
}

}  // namespace facedyn::sim
