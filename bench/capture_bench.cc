// capture_bench: the recording path's sustained throughput next to the disk's own sequential
// write speed measured in the same run on the same folder, and the simulated renderer's
// frames/s. Prints JSON on stdout.
//
//   capture_bench [--dir DIR] [--cameras N] [--width W] [--height H] [--megabytes MB]
//                 [--fps F] [--render-frames K]
//
// disk: one file written sequentially in frame-sized write() calls, then fdatasync (what
//   `dd conv=fdatasync` measures); MB/s = bytes / (write + sync time).
// disk_parallel: N threads each writing its own file the way the recorder's writers do
//   (frame-sized writes, writeback started per write, fdatasync), without queues or frames:
//   recording / disk_parallel is what the recorder itself costs.
// recording_max: N producer threads push distinct pre-filled frames as fast as the recorder
//   accepts them (back-pressure "block"), N writer threads write N frame files; the clock
//   stops after Finish() (which fdatasyncs every file). ratio = recording / disk.
// recording_realtime: the same at the camera rate (N cameras x fps, paced) with "drop_newest",
//   for at most the time the data volume lasts: drops > 0 means the disk cannot sustain N
//   cameras at that rate; sustainable_cameras = recording_max MB/s / one camera's MB/s.
// render: FaceRenderer on the procedural face, one thread, at the camera size and at 320x256.

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "bench/bench_flags.h"
#include "capture/capture_config.h"
#include "capture/frame_file.h"
#include "capture/recorder.h"
#include "core/json_io.h"
#include "core/log.h"
#include "sim/procedural_face.h"
#include "sim/virtual_camera.h"

namespace {

using facedyn::Json;
using Clock = std::chrono::steady_clock;
namespace capture = facedyn::capture;

double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

struct Args {
  std::string dir = std::filesystem::temp_directory_path().string();
  int cameras = 8;
  int width = 1280;
  int height = 1024;
  double megabytes = 1024;
  double fps = 128;
  int render_frames = 40;
};

bool Parse(int argc, char** argv, Args* args) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&](const char* name) -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "capture_bench: %s needs a value\n", name);
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--dir")
      args->dir = next("--dir");
    else if (a == "--cameras")
      args->cameras = static_cast<int>(facedyn::bench::FlagInteger("capture_bench", "--cameras", next("--cameras")));
    else if (a == "--width")
      args->width = static_cast<int>(facedyn::bench::FlagInteger("capture_bench", "--width", next("--width")));
    else if (a == "--height")
      args->height = static_cast<int>(facedyn::bench::FlagInteger("capture_bench", "--height", next("--height")));
    else if (a == "--megabytes")
      args->megabytes = facedyn::bench::FlagNumber("capture_bench", "--megabytes", next("--megabytes"));
    else if (a == "--fps")
      args->fps = facedyn::bench::FlagNumber("capture_bench", "--fps", next("--fps"));
    else if (a == "--render-frames")
      args->render_frames = static_cast<int>(facedyn::bench::FlagInteger("capture_bench", "--render-frames", next("--render-frames")));
    else {
      std::fprintf(stderr, "capture_bench: unknown argument '%s'\n", a.c_str());
      return false;
    }
  }
  if (args->cameras < 1 || args->width < 16 || args->height < 16 || args->megabytes < 16 ||
      args->fps <= 0 || args->render_frames < 1) {
    std::fprintf(
        stderr,
        "capture_bench: --cameras >= 1, --width/--height >= 16, --megabytes >= 16, --fps > 0\n");
    return false;
  }
  return true;
}

// Sequential write of `bytes` in `chunk`-sized writes + fdatasync. MB/s, or < 0 on error.
double DiskWriteMbPerS(const std::string& path, size_t bytes, size_t chunk,
                       bool start_writeback = false) {
  std::vector<uint8_t> buffer(chunk);
  for (size_t i = 0; i < chunk; ++i) buffer[i] = static_cast<uint8_t>(i * 131 + 7);
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return -1;
  const auto start = Clock::now();
  size_t written = 0;
  while (written < bytes) {
    buffer[0] = static_cast<uint8_t>(written / chunk);  // distinct blocks
    const ssize_t n = ::write(fd, buffer.data(), std::min(chunk, bytes - written));
    if (n <= 0) {
      ::close(fd);
      return -1;
    }
    if (start_writeback)
      ::sync_file_range(fd, static_cast<off64_t>(written), n, SYNC_FILE_RANGE_WRITE);
    written += static_cast<size_t>(n);
  }
  ::fdatasync(fd);
  const double s = Seconds(start);
  ::close(fd);
  ::unlink(path.c_str());
  return bytes / 1e6 / s;
}

// N files written concurrently, `bytes` in all. MB/s.
double ParallelDiskMbPerS(const std::string& dir, int files, size_t bytes, size_t chunk) {
  std::vector<std::thread> threads;
  const auto start = Clock::now();
  std::atomic<bool> failed{false};
  for (int k = 0; k < files; ++k) {
    threads.emplace_back([&, k] {
      if (DiskWriteMbPerS(dir + "/parallel" + std::to_string(k) + ".bin", bytes / files, chunk,
                          true) < 0)
        failed = true;
    });
  }
  for (auto& t : threads) t.join();
  return failed ? -1 : bytes / 1e6 / Seconds(start);
}

struct RecordingResult {
  double mb_per_s = 0;
  double seconds = 0;
  int64_t frames = 0;
  int64_t dropped = 0;
  std::string error;
};

RecordingResult Record(const Args& args, const std::string& dir, int64_t frames_per_camera,
                       capture::BackpressurePolicy policy, double pace_fps) {
  RecordingResult result;
  std::filesystem::remove_all(dir);
  std::vector<std::string> paths;
  for (int k = 0; k < args.cameras; ++k) {
    std::filesystem::create_directories(dir + "/cam" + std::to_string(k));
    paths.push_back(dir + "/cam" + std::to_string(k) + "/" + capture::kFrameFileName);
  }
  capture::RecorderOptions options;
  options.queue_frames = 16;
  options.policy = policy;
  capture::BufferPool pool(static_cast<size_t>(args.cameras) * 24);
  auto recorder = capture::Recorder::Start(options, paths, &pool);
  if (!recorder.ok()) {
    result.error = recorder.status().message();
    return result;
  }
  const size_t frame_bytes = static_cast<size_t>(args.width) * args.height;
  std::atomic<int64_t> dropped{0};
  const auto start = Clock::now();
  std::vector<std::thread> producers;
  for (int k = 0; k < args.cameras; ++k) {
    producers.emplace_back([&, k] {
      for (int64_t t = 0; t < frames_per_camera; ++t) {
        if (pace_fps > 0)
          std::this_thread::sleep_until(
              start + std::chrono::nanoseconds(static_cast<int64_t>(t * 1e9 / pace_fps)));
        capture::Frame frame;
        frame.camera_index = k;
        frame.trigger_index = t;
        frame.timestamp_ns = static_cast<int64_t>(t * 1e9 / args.fps);
        frame.width_px = args.width;
        frame.height_px = args.height;
        frame.pixels = pool.Acquire(frame_bytes);
        // Touch every page like a camera DMA would, cheaply.
        for (size_t i = 0; i < frame_bytes; i += 4096)
          frame.pixels[i] = static_cast<uint8_t>(t + k);
        if ((*recorder)->Push(k, std::move(frame)) == capture::PushResult::kDropped) ++dropped;
      }
    });
  }
  for (auto& p : producers) p.join();
  const facedyn::Status status = (*recorder)->Finish();
  result.seconds = Seconds(start);
  if (!status.ok()) result.error = status.message();
  double bytes = 0;
  for (const auto& stats : (*recorder)->stats()) {
    bytes += static_cast<double>(stats.bytes_written);
    result.frames += stats.frames_written;
  }
  result.dropped = dropped;
  result.mb_per_s = bytes / 1e6 / result.seconds;
  std::filesystem::remove_all(dir);
  return result;
}

Json RenderFps(int width, int height, double focal, int frames, const facedyn::FaceRig& rig) {
  facedyn::sim::RenderOptions options;
  facedyn::sim::FaceRenderer renderer(rig, options);
  capture::CameraRing ring;
  ring.count = 1;
  ring.width_px = width;
  ring.height_px = height;
  ring.focal_px = focal;
  ring.k1 = -0.08;
  const capture::CameraModel camera = ring.Cameras()[0];
  facedyn::sim::RenderWorkspace workspace;
  std::vector<uint8_t> image(static_cast<size_t>(width) * height);
  renderer.Render(camera, rig.neutral.positions_mm, 0, &workspace, image.data());  // warm up
  const auto start = Clock::now();
  for (int f = 0; f < frames; ++f)
    renderer.Render(camera, rig.neutral.positions_mm, f, &workspace, image.data());
  const double s = Seconds(start);
  return Json{{"width_px", width},
              {"height_px", height},
              {"frames", frames},
              {"frames_per_s_one_thread", frames / s}};
}

}  // namespace

int main(int argc, char** argv) {
  facedyn::InitLogging(facedyn::Verbosity::kQuiet);
  Args args;
  if (!Parse(argc, argv, &args)) return 2;
  const std::string dir = args.dir + "/facedyn_capture_bench_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  const size_t frame_bytes = static_cast<size_t>(args.width) * args.height;
  const size_t total_bytes = static_cast<size_t>(args.megabytes * 1e6);
  const int64_t frames_per_camera = std::max<int64_t>(1, total_bytes / frame_bytes / args.cameras);
  const size_t recorded_bytes = static_cast<size_t>(frames_per_camera) * args.cameras *
                                (frame_bytes + capture::kFrameHeaderBytes);

  Json out;
  out["machine"] = {{"hardware_threads", std::thread::hardware_concurrency()}, {"dir", args.dir}};
  out["frame"] = {{"width_px", args.width},
                  {"height_px", args.height},
                  {"format", "mono8"},
                  {"bytes", frame_bytes}};
  // Disk and recording alternate (disk, record, disk, record, disk) and each figure is the
  // median of its runs: the first writes to a fresh virtual disk are slower than later ones,
  // and the page cache and the host change over a run.
  std::vector<double> disks, parallels;
  std::vector<RecordingResult> maxes;
  for (int round = 0; round < 3; ++round) {
    disks.push_back(DiskWriteMbPerS(dir + "/sequential.bin", recorded_bytes, frame_bytes));
    parallels.push_back(ParallelDiskMbPerS(dir, args.cameras, recorded_bytes, frame_bytes));
    if (round < 2)
      maxes.push_back(
          Record(args, dir + "/max", frames_per_camera, capture::BackpressurePolicy::kBlock, 0.0));
  }
  out["disk_runs_mb_per_s"] = disks;
  out["disk_parallel_runs_mb_per_s"] = parallels;
  std::sort(disks.begin(), disks.end());
  std::sort(parallels.begin(), parallels.end());
  const double disk = disks[1];
  out["disk_sequential_write_mb_per_s"] = disk;
  out["disk_parallel_write_mb_per_s"] = parallels[1];
  const RecordingResult max =
      maxes[0].mb_per_s < maxes[1].mb_per_s ? maxes[0] : maxes[1];  // the slower of two
  out["recording_runs_mb_per_s"] = Json::array({maxes[0].mb_per_s, maxes[1].mb_per_s});
  out["recording_max"] = {
      {"cameras", args.cameras},
      {"frames", max.frames},
      {"seconds", max.seconds},
      {"mb_per_s", max.mb_per_s},
      {"ratio_to_disk", disk > 0 ? max.mb_per_s / disk : 0.0},
      {"ratio_to_disk_parallel", parallels[1] > 0 ? max.mb_per_s / parallels[1] : 0.0},
      {"dropped", max.dropped},
      {"error", max.error.empty() ? Json(nullptr) : Json(max.error)}};
  const double camera_mb_per_s = frame_bytes * args.fps / 1e6;
  out["one_camera_mb_per_s"] = camera_mb_per_s;
  out["sustainable_cameras_at_fps"] = max.mb_per_s / camera_mb_per_s;

  const RecordingResult realtime = Record(args, dir + "/realtime", frames_per_camera,
                                          capture::BackpressurePolicy::kDropNewest, args.fps);
  out["recording_realtime"] = {
      {"cameras", args.cameras},
      {"fps", args.fps},
      {"frames_offered", frames_per_camera * args.cameras},
      {"frames_written", realtime.frames},
      {"dropped", realtime.dropped},
      {"required_mb_per_s", camera_mb_per_s * args.cameras},
      {"mb_per_s", realtime.mb_per_s},
      {"error", realtime.error.empty() ? Json(nullptr) : Json(realtime.error)}};

  auto rig = facedyn::sim::MakeProceduralFace(facedyn::sim::ProceduralFaceOptions());
  if (!rig.ok()) {
    std::fprintf(stderr, "capture_bench: %s\n", rig.status().message().c_str());
    return 1;
  }
  out["render"] = Json::array(
      {RenderFps(args.width, args.height, 3600.0 * args.width / 1280, args.render_frames, *rig),
       RenderFps(320, 256, 900, args.render_frames * 4, *rig)});
  out["render_vertices"] = rig->vertex_count();
  std::filesystem::remove_all(dir);
  std::printf("%s\n", out.dump(2).c_str());
  return 0;
}
