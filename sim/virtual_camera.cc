#include "sim/virtual_camera.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

namespace facedyn::sim {
namespace {

constexpr int kNoiseTableBits = 16;
constexpr float kInfinity = std::numeric_limits<float>::infinity();

// 2^16 standard normal samples, fixed seed: per-pixel noise is a table lookup at a hashed
// index, which is deterministic and costs a few nanoseconds instead of a Box-Muller.
const std::vector<float>& NoiseTable() {
  static const std::vector<float> table = [] {
    std::vector<float> values(1u << kNoiseTableBits);
    std::mt19937_64 rng(0x5eed);
    std::normal_distribution<float> normal(0.0f, 1.0f);
    for (float& v : values) v = normal(rng);
    return values;
  }();
  return table;
}

inline uint64_t SplitMix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// The sensor's noise and quantisation, pixel by pixel: out = round(clamp(dn + sigma(dn) n)) with
// dn = radiance x scale, sigma^2 = read_var + shot x dn and n the table's normal sample at
// SplitMix64(key + pixel index). Eight pixels at a time with GCC's vector extension (the
// hash's 64-bit products in lanes; the scalar loop does not vectorise, and it was half of
// rendering's time), built for AVX2 too and picked at load time as
// reconstruct/marker_detection.cc's fit. The scalar loop finishes the last pixels; the AVX2
// variant's fused multiply-add rounds differently at exactly half a grey level (on a captured
// 8-frame sim8 take, 2 of 10.5 million pixels came out one level apart).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v3", "default")))
#endif
void AddNoiseAndQuantise(const float* radiance, size_t pixels, float scale, float read_var,
                         float shot, uint64_t key, const float* noise, uint8_t* out) {
  typedef float Floats __attribute__((vector_size(8 * sizeof(float))));
  typedef uint64_t Words __attribute__((vector_size(8 * sizeof(uint64_t))));
  typedef int32_t Ints __attribute__((vector_size(8 * sizeof(int32_t))));
  typedef uint8_t Bytes __attribute__((vector_size(8)));
  constexpr uint64_t kMask = (uint64_t{1} << kNoiseTableBits) - 1;
  const Words lane = {0, 1, 2, 3, 4, 5, 6, 7};
  size_t i = 0;
  for (; i + 8 <= pixels; i += 8) {
    Floats r;
    std::memcpy(&r, radiance + i, sizeof(r));
    const Floats dn = r * scale;
    const Floats variance = read_var + shot * (dn > 0.0f ? dn : 0.0f);
    Words x = (key + i) + lane;  // SplitMix64, lane-wise
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    x = x ^ (x >> 31);
    Floats sigma, n;
    for (int j = 0; j < 8; ++j) {
      sigma[j] = std::sqrt(variance[j]);
      n[j] = noise[x[j] & kMask];
    }
    Floats value = dn + sigma * n;
    value = value > 0.0f ? value : 0.0f;
    value = value < 255.0f ? value : 255.0f;
    const Bytes rounded =
        __builtin_convertvector(__builtin_convertvector(value + 0.5f, Ints), Bytes);
    std::memcpy(out + i, &rounded, sizeof(rounded));
  }
  for (; i < pixels; ++i) {
    const float dn = radiance[i] * scale;
    const float sigma = std::sqrt(read_var + shot * (dn > 0.0f ? dn : 0.0f));
    const float n = noise[SplitMix64(key + i) & kMask];
    // Rounded to nearest by truncating value + 0.5 after the clamp (the value is then
    // non-negative): std::round was a libm call per pixel.
    float value = dn + sigma * n;
    value = value > 0.0f ? value : 0.0f;
    value = value < 255.0f ? value : 255.0f;
    out[i] = static_cast<uint8_t>(static_cast<int>(value + 0.5f));
  }
}

capture::Intrinsics SupersampledIntrinsics(const capture::CameraModel& camera, int s) {
  capture::Intrinsics k = camera.intrinsics;
  k[0] *= s;
  k[1] *= s;
  k[2] = k[2] * s + (s - 1) / 2.0;  // pixel centres: (0,0) is the centre of the top-left pixel
  k[3] = k[3] * s + (s - 1) / 2.0;
  return k;
}

}  // namespace

Status RenderOptions::Check() const {
  auto in01 = [](double v) { return v >= 0.0 && v <= 1.0; };
  if (!in01(skin_albedo)) return InvalidArgumentError("render.skin_albedo must be in [0, 1]");
  if (!in01(marker_albedo)) return InvalidArgumentError("render.marker_albedo must be in [0, 1]");
  if (!in01(background)) return InvalidArgumentError("render.background must be in [0, 1]");
  if (!in01(ambient)) return InvalidArgumentError("render.ambient must be in [0, 1]");
  if (!(gain > 0 && gain < 100)) return InvalidArgumentError("render.gain must be in (0, 100)");
  if (!(read_noise_dn >= 0 && read_noise_dn < 100))
    return InvalidArgumentError("render.read_noise_dn must be in [0, 100)");
  if (!(shot_noise_gain >= 0 && shot_noise_gain < 100))
    return InvalidArgumentError("render.shot_noise_gain must be in [0, 100)");
  if (!(blur_sigma_px >= 0 && blur_sigma_px <= 10))
    return InvalidArgumentError("render.blur_sigma_px must be in [0, 10]");
  if (motion_blur_samples < 1 || motion_blur_samples > 64)
    return InvalidArgumentError("render.motion_blur_samples must be in 1..64");
  if (supersample < 1 || supersample > 4)
    return InvalidArgumentError("render.supersample must be in 1..4");
  return Status::Ok();
}

void RenderWorkspace::Resize(int width, int height, int vertices) {
  const size_t pixels = static_cast<size_t>(width) * height;
  width_px = width;
  height_px = height;
  if (radiance.size() != pixels) {
    radiance.assign(pixels, 0.0f);
    sample.assign(pixels, 0.0f);
    depth_mm.assign(pixels, kInfinity);
  }
  if (static_cast<int>(shade.size()) != vertices) {
    projected.assign(3 * static_cast<size_t>(vertices), 0.0f);
    shade.assign(vertices, 0.0f);
    normals.resize(3, vertices);
  }
}

FaceRenderer::FaceRenderer(const FaceRig& rig, const RenderOptions& options) : options_(options) {
  FACEDYN_CHECK(options.Check().ok(), "FaceRenderer: " + options.Check().message());
  triangles_ = rig.neutral.Triangles();
  rest_ = rig.neutral.positions_mm;
  const int triangle_count = static_cast<int>(triangles_.cols());
  // Front side: the winding whose normals point away from the mesh centroid (inside the head).
  const Eigen::Vector3d centre = rest_.rowwise().mean();
  double outward = 0.0;
  Eigen::Matrix3Xd centroids(3, triangle_count);
  std::vector<double> bound_radius(triangle_count);
  for (int t = 0; t < triangle_count; ++t) {
    const Eigen::Vector3d a = rest_.col(triangles_(0, t)), b = rest_.col(triangles_(1, t)),
                          c = rest_.col(triangles_(2, t));
    centroids.col(t) = (a + b + c) / 3.0;
    outward += ((b - a).cross(c - a)).dot(centroids.col(t) - centre);
    bound_radius[t] = std::max({(a - centroids.col(t)).norm(), (b - centroids.col(t)).norm(),
                                (c - centroids.col(t)).norm()});
  }
  outward_ccw_ = outward >= 0.0;
  marker_rest_.resize(3, rig.markers.size());
  for (size_t m = 0; m < rig.markers.size(); ++m) {
    marker_rest_.col(m) = rig.markers[m].point.Evaluate(rest_);
    marker_radius_mm_.push_back(rig.markers[m].diameter_mm / 2.0);
  }
  std::vector<std::vector<int>> lists(triangle_count);
  for (int m = 0; m < static_cast<int>(marker_radius_mm_.size()); ++m) {
    for (int t = 0; t < triangle_count; ++t) {
      if ((marker_rest_.col(m) - centroids.col(t)).norm() <=
          bound_radius[t] + marker_radius_mm_[m] + 0.5) {
        lists[t].push_back(m);
      }
    }
  }
  // Per (triangle, dot) pair: |p(w) - m|^2 for the rest-pose point p(w) = w0 a + w1 b +
  // (1 - w0 - w1) c, expanded in w0, w1 around c - m (double here, float per pixel).
  triangle_marker_offsets_.assign(1, 0);
  for (int t = 0; t < triangle_count; ++t) {
    const Eigen::Vector3d a = rest_.col(triangles_(0, t)), b = rest_.col(triangles_(1, t)),
                          c = rest_.col(triangles_(2, t));
    const Eigen::Vector3d e0 = a - c, e1 = b - c;
    for (const int m : lists[t]) {
      const Eigen::Vector3d p0 = c - marker_rest_.col(m);
      MarkerTerm term;
      term.c = {static_cast<float>(p0.squaredNorm()), static_cast<float>(2 * p0.dot(e0)),
                static_cast<float>(2 * p0.dot(e1)),   static_cast<float>(e0.squaredNorm()),
                static_cast<float>(2 * e0.dot(e1)),   static_cast<float>(e1.squaredNorm())};
      term.radius_mm = static_cast<float>(marker_radius_mm_[m]);
      marker_terms_.push_back(term);
    }
    triangle_marker_offsets_.push_back(static_cast<int>(marker_terms_.size()));
  }
}

void FaceRenderer::BeginFrame(const capture::CameraModel& camera, RenderWorkspace* ws) const {
  const int s = options_.supersample;
  ws->Resize(camera.width_px * s, camera.height_px * s, vertex_count());
  ws->instants = 0;  // the first instant sets the radiance rather than adding to zeros
}

void FaceRenderer::AccumulateInstant(const capture::CameraModel& camera,
                                     const Eigen::Matrix3Xd& positions, float weight,
                                     RenderWorkspace* ws) const {
  FACEDYN_CHECK(positions.cols() == vertex_count(), "FaceRenderer: vertex count mismatch");
  const int width = ws->width_px, height = ws->height_px;
  const capture::Intrinsics k = SupersampledIntrinsics(camera, options_.supersample);
  const Eigen::Matrix3d r = camera.cam_from_world.RotationMatrix();
  const Eigen::Vector3d t = camera.cam_from_world.translation();
  const Eigen::Vector3d centre = camera.CenterInWorld();
  const int v_count = vertex_count();
  const int triangle_count = static_cast<int>(triangles_.cols());

  // Per-vertex projection, normals and shading.
  float* projected = ws->projected.data();
  for (int v = 0; v < v_count; ++v) {
    const Eigen::Vector3d p = r * positions.col(v) + t;
    if (p.z() <= 1.0) {
      projected[3 * v + 2] = -1.0f;
      continue;
    }
    double u, w;
    capture::DistortAndScale(k.data(), p.x() / p.z(), p.y() / p.z(), &u, &w);
    projected[3 * v] = static_cast<float>(u);
    projected[3 * v + 1] = static_cast<float>(w);
    projected[3 * v + 2] = static_cast<float>(p.z());
  }
  ws->normals.setZero();
  const double orientation = outward_ccw_ ? 1.0 : -1.0;
  for (int f = 0; f < triangle_count; ++f) {
    const int a = triangles_(0, f), b = triangles_(1, f), c = triangles_(2, f);
    const Eigen::Vector3d n =
        orientation *
        (positions.col(b) - positions.col(a)).cross(positions.col(c) - positions.col(a));
    ws->normals.col(a) += n;
    ws->normals.col(b) += n;
    ws->normals.col(c) += n;
  }
  const double ambient = options_.ambient;
  for (int v = 0; v < v_count; ++v) {
    const double norm = ws->normals.col(v).norm();
    const Eigen::Vector3d to_light =
        (centre - positions.col(v)).normalized();  // ring light at the camera
    const double ndl = norm > 0 ? std::max(0.0, ws->normals.col(v).dot(to_light) / norm) : 0.0;
    ws->shade[v] = static_cast<float>(ambient + (1.0 - ambient) * ndl);
  }

  std::fill(ws->sample.begin(), ws->sample.end(), static_cast<float>(options_.background));
  std::fill(ws->depth_mm.begin(), ws->depth_mm.end(), kInfinity);
  float* sample = ws->sample.data();
  float* depth = ws->depth_mm.data();
  const float skin = static_cast<float>(options_.skin_albedo);
  const float paint = static_cast<float>(options_.marker_albedo);
  const float inv_focal = static_cast<float>(1.0 / k[0]);

  for (int f = 0; f < triangle_count; ++f) {
    const int ia = triangles_(0, f), ib = triangles_(1, f), ic = triangles_(2, f);
    const float za = projected[3 * ia + 2], zb = projected[3 * ib + 2], zc = projected[3 * ic + 2];
    if (za <= 0 || zb <= 0 || zc <= 0) continue;
    // Back-face culling in 3D (robust to distortion): the front side faces the camera.
    const Eigen::Vector3d n =
        orientation *
        (positions.col(ib) - positions.col(ia)).cross(positions.col(ic) - positions.col(ia));
    if (n.dot(centre - positions.col(ia)) <= 0) continue;
    const float ax = projected[3 * ia], ay = projected[3 * ia + 1];
    const float bx = projected[3 * ib], by = projected[3 * ib + 1];
    const float cx = projected[3 * ic], cy = projected[3 * ic + 1];
    const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({ax, bx, cx}))));
    const int x1 = std::min(width - 1, static_cast<int>(std::floor(std::max({ax, bx, cx}))));
    const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({ay, by, cy}))));
    const int y1 = std::min(height - 1, static_cast<int>(std::floor(std::max({ay, by, cy}))));
    if (x0 > x1 || y0 > y1) continue;
    const float area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    if (std::abs(area) < 1e-8f) continue;
    const float inv_area = 1.0f / area;
    // Barycentric l_i = edge_i(x, y) / area, linear in x and y.
    const float l0dx = (by - cy) * inv_area, l0dy = (cx - bx) * inv_area;
    const float l1dx = (cy - ay) * inv_area, l1dy = (ax - cx) * inv_area;
    const float l0c = ((bx - x0) * (cy - y0) - (by - y0) * (cx - x0)) * inv_area;
    const float l1c = ((cx - x0) * (ay - y0) - (cy - y0) * (ax - x0)) * inv_area;
    const float iza = 1.0f / za, izb = 1.0f / zb, izc = 1.0f / zc;
    const float sa = ws->shade[ia] * iza, sb = ws->shade[ib] * izb, sc = ws->shade[ic] * izc;
    const int marker_begin = triangle_marker_offsets_[f],
              marker_end = triangle_marker_offsets_[f + 1];
    for (int y = y0; y <= y1; ++y) {
      float l0 = l0c + l0dy * (y - y0);
      float l1 = l1c + l1dy * (y - y0);
      float* sample_row = sample + static_cast<size_t>(y) * width;
      float* depth_row = depth + static_cast<size_t>(y) * width;
      for (int x = x0; x <= x1; ++x, l0 += l0dx, l1 += l1dx) {
        const float l2 = 1.0f - l0 - l1;
        if (l0 < -1e-6f || l1 < -1e-6f || l2 < -1e-6f) continue;
        const float iz = l0 * iza + l1 * izb + l2 * izc;
        const float z = 1.0f / iz;
        if (z >= depth_row[x]) continue;
        depth_row[x] = z;
        const float shade = (l0 * sa + l1 * sb + l2 * sc) * z;
        float albedo = skin;
        if (marker_begin != marker_end) {
          // Perspective-correct barycentrics; each nearby dot's squared rest-pose distance is a
          // quadratic in them (MarkerTerm). Coverage is 0 beyond r + footprint / 2 and 1 within
          // r - footprint / 2, so only the dot's rim needs the square root.
          const float w0 = l0 * iza * z, w1 = l1 * izb * z;
          const float footprint_mm = z * inv_focal;
          float coverage = 0.0f;
          for (int i = marker_begin; i < marker_end; ++i) {
            const MarkerTerm& term = marker_terms_[i];
            const float d2 = term.c[0] + w0 * (term.c[1] + w0 * term.c[3] + w1 * term.c[4]) +
                             w1 * (term.c[2] + w1 * term.c[5]);
            const float outer = term.radius_mm + 0.5f * footprint_mm;
            if (d2 >= outer * outer) continue;
            const float inner = term.radius_mm - 0.5f * footprint_mm;
            if (inner > 0.0f && d2 <= inner * inner) {
              coverage = 1.0f;
              break;
            }
            const float d = std::sqrt(std::max(d2, 0.0f));
            coverage = std::max(coverage,
                                std::clamp((term.radius_mm - d) / footprint_mm + 0.5f, 0.0f, 1.0f));
          }
          albedo = skin + (paint - skin) * coverage;
        }
        sample_row[x] = shade * albedo;
      }
    }
  }
  // The first instant of a frame is the radiance (a whole instant, the usual case without
  // motion blur: the two buffers trade places, no pass over the image); later ones add to it.
  float* radiance = ws->radiance.data();
  const size_t pixels = ws->radiance.size();
  if (ws->instants == 0 && weight == 1.0f) {
    std::swap(ws->radiance, ws->sample);
  } else if (ws->instants == 0) {
    for (size_t i = 0; i < pixels; ++i) radiance[i] = weight * sample[i];
  } else {
    for (size_t i = 0; i < pixels; ++i) radiance[i] += weight * sample[i];
  }
  ++ws->instants;
}

void FinishRadiance(const RenderOptions& options, int width, int height, int s, uint64_t noise_key,
                    std::vector<float>* radiance, uint8_t* out) {
  float* data = radiance->data();
  if (s > 1) {  // box filter, in place into the first width x height floats
    const int hi_width = width * s;
    const float norm = 1.0f / (s * s);
    for (int y = 0; y < height; ++y) {
      for (int x = 0; x < width; ++x) {
        float sum = 0.0f;
        for (int dy = 0; dy < s; ++dy) {
          const float* row = data + static_cast<size_t>(y * s + dy) * hi_width + x * s;
          for (int dx = 0; dx < s; ++dx) sum += row[dx];
        }
        data[static_cast<size_t>(y) * width + x] = sum * norm;  // never overwrites unread input
      }
    }
  }
  if (options.blur_sigma_px > 0) {
    cv::Mat image(height, width, CV_32F, data);
    cv::GaussianBlur(image, image, cv::Size(0, 0), options.blur_sigma_px, options.blur_sigma_px,
                     cv::BORDER_REPLICATE);
  }
  const float scale = static_cast<float>(255.0 * options.gain);
  const float read_var = static_cast<float>(options.read_noise_dn * options.read_noise_dn);
  const float shot = static_cast<float>(options.shot_noise_gain);
  const uint64_t key = SplitMix64(noise_key ^ (options.seed * 0x9e3779b97f4a7c15ull));
  AddNoiseAndQuantise(data, static_cast<size_t>(width) * height, scale, read_var, shot, key,
                      NoiseTable().data(), out);
}

void FaceRenderer::FinishFrame(const capture::CameraModel& camera, uint64_t noise_key,
                               RenderWorkspace* ws, uint8_t* out) const {
  if (ws->instants == 0) std::fill(ws->radiance.begin(), ws->radiance.end(), 0.0f);
  FinishRadiance(options_, camera.width_px, camera.height_px, options_.supersample, noise_key,
                 &ws->radiance, out);
}

void FaceRenderer::Render(const capture::CameraModel& camera, const Eigen::Matrix3Xd& positions,
                          uint64_t noise_key, RenderWorkspace* ws, uint8_t* out) const {
  BeginFrame(camera, ws);
  AccumulateInstant(camera, positions, 1.0f, ws);
  FinishFrame(camera, noise_key, ws, out);
}

// ------------------------------------------------------------------------------- SimCamera

SimCamera::SimCamera(int camera_index, capture::CameraModel model,
                     std::shared_ptr<const FaceRenderer> renderer, std::shared_ptr<const Take> take,
                     SimCameraFaults faults)
    : camera_index_(camera_index),
      model_(std::move(model)),
      renderer_(std::move(renderer)),
      take_(std::move(take)),
      faults_(std::move(faults)) {
  FACEDYN_CHECK(renderer_ && take_, "SimCamera needs a renderer and a take");
}

Status SimCamera::Configure(const capture::CameraSettings& settings) {
  FACEDYN_RETURN_IF_ERROR(settings.Check());
  if (settings.width_px != model_.width_px || settings.height_px != model_.height_px) {
    return InvalidArgumentError(
        "camera " + model_.name + ": requested " + std::to_string(settings.width_px) + "x" +
        std::to_string(settings.height_px) + " but its calibration is " +
        std::to_string(model_.width_px) + "x" + std::to_string(model_.height_px));
  }
  if (settings.format != capture::PixelFormat::kMono8) {
    return InvalidArgumentError("camera " + model_.name + ": the simulated camera is mono8 only");
  }
  if (std::abs(settings.fps - take_->info.fps) > 1e-6) {
    return InvalidArgumentError(
        "camera " + model_.name + ": trigger rate " + std::to_string(settings.fps) +
        " fps differs from the simulated take's " + std::to_string(take_->info.fps) + " fps");
  }
  if (renderer_->vertex_count() != take_->vertex_count()) {
    return FailedPreconditionError("camera " + model_.name +
                                   ": the take's vertex count differs from the face rig's");
  }
  settings_ = settings;
  configured_ = true;
  return Status::Ok();
}

Status SimCamera::Arm() {
  if (!configured_)
    return FailedPreconditionError("camera " + model_.name + ": Arm before Configure");
  std::lock_guard<std::mutex> lock(mutex_);
  pending_.clear();
  disarmed_ = false;
  armed_ = true;
  has_late_ = has_repeat_ = false;
  return Status::Ok();
}

Status SimCamera::OnTrigger(const capture::TriggerEvent& trigger) {
  std::unique_lock<std::mutex> lock(mutex_);
  if (!armed_)
    return FailedPreconditionError("camera " + model_.name + ": trigger while not armed");
  changed_.wait(lock, [&] { return pending_.size() < 8 || disarmed_; });
  if (disarmed_) return Status::Ok();
  pending_.push_back(trigger);
  changed_.notify_all();
  return Status::Ok();
}

Status SimCamera::Disarm() {
  std::lock_guard<std::mutex> lock(mutex_);
  disarmed_ = true;
  changed_.notify_all();
  return Status::Ok();
}

Status SimCamera::RenderTrigger(const capture::TriggerEvent& trigger, capture::Frame* frame) {
  const int frame_count = take_->frame_count();
  if (trigger.index >= frame_count) {
    return FailedPreconditionError(
        "camera " + model_.name + ": trigger " + std::to_string(trigger.index) +
        " is beyond the simulated take's " + std::to_string(frame_count) + " frames");
  }
  const auto start = std::chrono::steady_clock::now();
  frame->camera_index = camera_index_;
  frame->trigger_index = trigger.index;
  frame->timestamp_ns = trigger.time_ns + faults_.timestamp_offset_ns;
  frame->exposure_us = settings_.exposure_us;
  frame->width_px = model_.width_px;
  frame->height_px = model_.height_px;
  frame->format = capture::PixelFormat::kMono8;
  frame->pixels.resize(frame->ExpectedBytes());
  const int samples = renderer_->options().motion_blur_samples;
  const int f = static_cast<int>(trigger.index);
  renderer_->BeginFrame(model_, &workspace_);
  positions_ = take_->positions.Frame(f).cast<double>();
  if (samples == 1 || f + 1 >= frame_count) {
    renderer_->AccumulateInstant(model_, positions_, 1.0f, &workspace_);
  } else {
    // Instants spread over the exposure, positions interpolated linearly between frames.
    const double exposure_frames = settings_.exposure_us * 1e-6 * settings_.fps;
    current_ = positions_;
    next_ = take_->positions.Frame(f + 1).cast<double>();
    for (int i = 0; i < samples; ++i) {
      const double a = exposure_frames * (i + 0.5) / samples;
      positions_ = (1.0 - a) * current_ + a * next_;
      renderer_->AccumulateInstant(model_, positions_, 1.0f / samples, &workspace_);
    }
  }
  renderer_->FinishFrame(
      model_, (static_cast<uint64_t>(camera_index_) << 40) ^ static_cast<uint64_t>(trigger.index),
      &workspace_, frame->pixels.data());
  render_s_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return Status::Ok();
}

Status SimCamera::NextFrame(double timeout_s, capture::Frame* frame, bool* got_frame) {
  *got_frame = false;
  for (;;) {
    if (has_repeat_) {  // a duplicated frame, delivered right after its original
      has_repeat_ = false;
      *frame = repeat_frame_;
      *got_frame = true;
      return Status::Ok();
    }
    capture::TriggerEvent trigger;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      const bool ready = changed_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                                           [&] { return !pending_.empty() || disarmed_; });
      if (pending_.empty()) {
        if (has_late_) {  // the late frame had nothing after it: deliver it now
          has_late_ = false;
          *frame = std::move(late_frame_);
          *got_frame = true;
          return Status::Ok();
        }
        if (disarmed_) return AbortedError("camera " + model_.name + ": disarmed");
        if (!ready) return Status::Ok();  // nothing within the timeout
        continue;
      }
      trigger = pending_.front();
      pending_.pop_front();
      changed_.notify_all();
    }
    if (faults_.drop_triggers.count(trigger.index)) continue;
    FACEDYN_RETURN_IF_ERROR(RenderTrigger(trigger, frame));
    if (faults_.late_triggers.count(trigger.index) && !has_late_) {
      late_frame_ = std::move(*frame);
      has_late_ = true;
      continue;
    }
    if (faults_.duplicate_triggers.count(trigger.index)) {
      repeat_frame_ = *frame;
      has_repeat_ = true;
    }
    if (has_late_) {  // deliver this frame now and the late one next
      repeat_frame_ = std::move(late_frame_);
      has_late_ = false;
      has_repeat_ = true;
    }
    *got_frame = true;
    return Status::Ok();
  }
}

}  // namespace facedyn::sim
