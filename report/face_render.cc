#include "report/face_render.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/check.h"

namespace facedyn::report {

std::vector<unsigned char> RenderSignedOffsetPng(const Mesh& topology,
                                                 const Eigen::Matrix3Xf& positions_in_skull,
                                                 const Eigen::Matrix3Xf& offsets_in_skull,
                                                 const OffsetRenderOptions& options) {
  const int vertex_count = topology.vertex_count();
  FACEDYN_CHECK(
      positions_in_skull.cols() == vertex_count && offsets_in_skull.cols() == vertex_count,
      "RenderSignedOffsetPng: sizes differ from the topology");
  const Eigen::Matrix3Xi triangles = topology.Triangles();
  FACEDYN_CHECK(triangles.cols() > 0, "RenderSignedOffsetPng: no faces");

  // Area-weighted vertex normals, oriented toward +Z on average (the face looks along +Z).
  Eigen::Matrix3Xf normals = Eigen::Matrix3Xf::Zero(3, vertex_count);
  for (int f = 0; f < triangles.cols(); ++f) {
    const Eigen::Vector3f a = positions_in_skull.col(triangles(0, f));
    const Eigen::Vector3f n = (positions_in_skull.col(triangles(1, f)) - a)
                                  .cross(positions_in_skull.col(triangles(2, f)) - a);
    for (int k = 0; k < 3; ++k) normals.col(triangles(k, f)) += n;
  }
  if (normals.row(2).sum() < 0) normals = -normals;
  for (int v = 0; v < vertex_count; ++v) {
    const float length = normals.col(v).norm();
    if (length > 0) normals.col(v) /= length;
  }
  Eigen::VectorXf signed_mm(vertex_count);
  for (int v = 0; v < vertex_count; ++v) signed_mm[v] = normals.col(v).dot(offsets_in_skull.col(v));

  // Fit the face's x-y extent into the image with a margin.
  const Eigen::Vector3f lo = positions_in_skull.rowwise().minCoeff();
  const Eigen::Vector3f hi = positions_in_skull.rowwise().maxCoeff();
  const float scale = 0.92f * std::min(options.width_px / std::max(hi.x() - lo.x(), 1e-3f),
                                       options.height_px / std::max(hi.y() - lo.y(), 1e-3f));
  const Eigen::Vector2f centre = 0.5f * (lo.head<2>() + hi.head<2>());
  auto to_pixel = [&](const Eigen::Vector3f& p) {
    return cv::Point(
        static_cast<int>(std::lround(options.width_px / 2.0 + scale * (p.x() - centre.x()))),
        static_cast<int>(std::lround(options.height_px / 2.0 - scale * (p.y() - centre.y()))));
  };

  std::vector<int> order(triangles.cols());
  std::iota(order.begin(), order.end(), 0);
  std::vector<float> depth(triangles.cols());
  for (int f = 0; f < triangles.cols(); ++f) {
    depth[f] = positions_in_skull(2, triangles(0, f)) + positions_in_skull(2, triangles(1, f)) +
               positions_in_skull(2, triangles(2, f));
  }
  std::sort(order.begin(), order.end(), [&depth](int a, int b) { return depth[a] < depth[b]; });

  cv::Mat image(options.height_px, options.width_px, CV_8UC3, cv::Scalar(255, 255, 255));
  const Eigen::Vector3f light = Eigen::Vector3f(0.3f, 0.4f, 1.0f).normalized();
  for (int f : order) {
    const int a = triangles(0, f), b = triangles(1, f), c = triangles(2, f);
    const Eigen::Vector3f face_normal =
        (positions_in_skull.col(b) - positions_in_skull.col(a))
            .cross(positions_in_skull.col(c) - positions_in_skull.col(a))
            .normalized();
    const float shade = 0.35f + 0.65f * std::abs(face_normal.dot(light));
    const float value = (signed_mm[a] + signed_mm[b] + signed_mm[c]) / 3.0f;
    const float t = std::clamp(value / static_cast<float>(options.range_mm), -1.0f, 1.0f);
    // Grey (200) at zero, toward red for t > 0 and green for t < 0.
    const float grey = 200.0f;
    float red = grey, green = grey, blue = grey;
    if (t > 0) {
      red = grey + (255 - grey) * t;
      green = grey * (1 - t);
      blue = grey * (1 - t);
    } else {
      green = grey + (255 - grey) * (-t);
      red = grey * (1 + t);
      blue = grey * (1 + t);
    }
    const cv::Point corners[3] = {to_pixel(positions_in_skull.col(a)),
                                  to_pixel(positions_in_skull.col(b)),
                                  to_pixel(positions_in_skull.col(c))};
    cv::fillConvexPoly(image, corners, 3, cv::Scalar(blue * shade, green * shade, red * shade),
                       cv::LINE_AA);
  }
  std::vector<unsigned char> png;
  cv::imencode(".png", image, png);
  return png;
}

std::string Base64(const std::vector<unsigned char>& bytes) {
  static const char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t k = 0;
  for (; k + 2 < bytes.size(); k += 3) {
    const unsigned v = (bytes[k] << 16) | (bytes[k + 1] << 8) | bytes[k + 2];
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (k < bytes.size()) {
    const unsigned v = (bytes[k] << 16) | (k + 1 < bytes.size() ? bytes[k + 1] << 8 : 0);
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += k + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

}  // namespace facedyn::report
