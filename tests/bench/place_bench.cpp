// Place recognition (issue 41): one online step (HOG of the frame, its
// similarities to every database image, Eq. 5.3-5.4, the filter's step) for
// databases of 2,400 and 10,000 images, on real Nordland frames (summer as
// the database, cycled to fill it; winter as the queries) at their 64 x 32
// pixels and enlarged to 128 x 64 and 320 x 160; and HOG alone.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <string>
#include <vector>

#include "trailnav/drivers/camera/image_file.hpp"
#include "trailnav/perception/place/online.hpp"

namespace {

using namespace trailnav::perception::place;
namespace camera = trailnav::drivers::camera;

std::vector<std::uint8_t> frame(const std::string& season, int number, int zoom) {
  char name[96];
  std::snprintf(name, sizeof name, "../shared/data/nordland/%s/images-%05d.png", season.c_str(), number);
  const camera::ImageRead r = camera::read_grey_image(name);
  if (!r.ok()) return {};
  if (zoom == 1) return r.image.pixels;
  std::vector<std::uint8_t> big(static_cast<std::size_t>(r.image.width * zoom * r.image.height * zoom));
  for (int y = 0; y < r.image.height * zoom; ++y)
    for (int x = 0; x < r.image.width * zoom; ++x)
      big[static_cast<std::size_t>(y * r.image.width * zoom + x)] =
          r.image.pixels[static_cast<std::size_t>((y / zoom) * r.image.width + x / zoom)];
  return big;
}

// A database of `images` summer frames (240 real ones, cycled), finished;
// false when the data is not there.
bool fill_summer(OnlinePlace& place, std::size_t images, int zoom, int width) {
  std::vector<std::vector<float>> summer;
  for (int k = 0; k < 240; ++k) {
    const std::vector<std::uint8_t> f = frame("summer", 100 + 100 * k, zoom);
    if (f.empty()) return false;
    const auto d = place.describe(f, width);
    summer.emplace_back(d.begin(), d.end());
  }
  for (std::size_t j = 0; j < images; ++j) place.add_database(summer[j % summer.size()]);
  place.finish_database();
  return true;
}

// Arguments: database images, zoom of the 64 x 32 frames.
void BM_PlaceStep(benchmark::State& state) {
  const auto images = static_cast<std::size_t>(state.range(0));
  const int zoom = static_cast<int>(state.range(1));
  OnlineConfig config;
  config.width = 64 * zoom;
  config.height = 32 * zoom;
  config.capacity = images;
  OnlinePlace place(config);
  if (!fill_summer(place, images, zoom, config.width)) {
    state.SkipWithError("../shared/data/nordland not found (run from the repository's root)");
    return;
  }
  std::vector<std::vector<std::uint8_t>> winter;
  for (int k = 0; k < 16; ++k) winter.push_back(frame("winter", 5000 + 100 * k, zoom));
  std::size_t k = 0;
  for (auto _ : state) {
    const auto& f = winter[k++ % winter.size()];
    const PlaceEstimate e = place.step(place.describe(f, config.width));
    benchmark::DoNotOptimize(e);
  }
  state.counters["descriptor"] = place.descriptor_length();
  state.counters["database_MB"] = static_cast<double>(images * place.bytes_per_image()) / 1e6;
}
// The same with ZCA for the robot (a whitening of rank 200, as place-map
// keeps; random directions: the timing is the same), and with the fixed lag
// and the online sequence test as trailnavd runs them (lag 10, l_s 10).
// Arguments: database images, lag.
void BM_PlaceStepZca(benchmark::State& state) {
  const auto images = static_cast<std::size_t>(state.range(0));
  OnlineConfig config;
  config.width = 64;
  config.height = 32;
  config.capacity = images;
  config.lag = static_cast<int>(state.range(1));
  config.sequence = {config.lag > 0 ? 10 : 0, 5, 5};
  OnlinePlace place(config);
  if (!fill_summer(place, images, 1, config.width)) {
    state.SkipWithError("../shared/data/nordland not found (run from the repository's root)");
    return;
  }
  Whitening w;
  w.rank = 200;
  w.base = 3.0f;
  w.mean.assign(images, 0.5f);
  w.gains.assign(200, -1.0f);
  w.directions.resize(images * 200);
  for (std::size_t i = 0; i < w.directions.size(); ++i) w.directions[i] = static_cast<float>((i * 2654435761u) % 1000) * 1e-5f;
  place.set_whitening(w);
  std::vector<std::vector<std::uint8_t>> winter;
  for (int k = 0; k < 16; ++k) winter.push_back(frame("winter", 5000 + 100 * k, 1));
  std::size_t k = 0;
  for (auto _ : state) {
    const PlaceEstimate e = place.step(place.describe(winter[k++ % winter.size()], config.width));
    benchmark::DoNotOptimize(e);
  }
  state.counters["whitening_MB"] = static_cast<double>(images * (200 + 4)) / 1e6;  // directions as bytes, the means as floats
  // The lag's ring: a likelihood row (float) and a forward belief (double)
  // per image and lagged frame, and the smoothed belief.
  state.counters["lag_MB"] = static_cast<double>(images * ((static_cast<std::size_t>(config.lag) + 1) * 12 + 8)) / 1e6;
}
BENCHMARK(BM_PlaceStepZca)->Args({2400, 0})->Args({10000, 0})->Args({2400, 10})->Args({10000, 10})->Unit(benchmark::kMillisecond);

BENCHMARK(BM_PlaceStep)->Args({2400, 1})->Args({10000, 1})->Args({10000, 2})->Args({10000, 5})->Unit(benchmark::kMillisecond);

void BM_Hog(benchmark::State& state) {
  const int zoom = static_cast<int>(state.range(0));
  const std::vector<std::uint8_t> f = frame("winter", 5000, zoom);
  if (f.empty()) {
    state.SkipWithError("../shared/data/nordland not found");
    return;
  }
  Hog hog(HogConfig{0}, 64 * zoom, 32 * zoom);
  std::vector<float> out(static_cast<std::size_t>(hog.length()));
  for (auto _ : state) {
    hog.compute(f, 64 * zoom, out);
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["pixels"] = 64.0 * 32.0 * zoom * zoom;
}
BENCHMARK(BM_Hog)->Arg(1)->Arg(5)->Arg(10)->Unit(benchmark::kMicrosecond);

}  // namespace


// The camera driver's conversion of one frame to the descriptor's 64 x 32:
// YUYV and MJPEG (libturbojpeg, quality 90) at 640 x 480 from a real Nordland
// frame enlarged.
#include <turbojpeg.h>

#include "trailnav/drivers/camera/frame.hpp"

namespace {

void BM_CameraFrame(benchmark::State& state) {
  namespace camera = trailnav::drivers::camera;
  const bool mjpeg = state.range(0) == 1;
  const int w = 640, h = 480;
  const std::vector<std::uint8_t> grey = frame("winter", 5000, 10);  // 640 x 320
  if (grey.empty()) {
    state.SkipWithError("../shared/data/nordland not found");
    return;
  }
  std::vector<std::uint8_t> yuyv(static_cast<std::size_t>(w * h * 2), 128), rgb(static_cast<std::size_t>(w * h * 3));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::uint8_t v = grey[static_cast<std::size_t>((y * 320 / h) * 640 + x)];
      yuyv[static_cast<std::size_t>((y * w + x) * 2)] = v;
      for (int c = 0; c < 3; ++c) rgb[static_cast<std::size_t>((y * w + x) * 3 + c)] = v;
    }
  std::vector<std::uint8_t> bytes = yuyv;
  if (mjpeg) {
    tjhandle enc = tjInitCompress();
    unsigned char* jpeg = nullptr;
    unsigned long size = 0;
    tjCompress2(enc, rgb.data(), w, 0, h, TJPF_RGB, &jpeg, &size, TJSAMP_422, 90, 0);
    bytes.assign(jpeg, jpeg + size);
    tjFree(jpeg);
    tjDestroy(enc);
  }
  camera::FrameConverter conv(mjpeg ? camera::PixelFormat::mjpeg : camera::PixelFormat::yuyv, w, h, 64, 32);
  for (auto _ : state) {
    if (!conv.convert(bytes, mjpeg ? 0 : 2 * w)) state.SkipWithError(conv.error());
    benchmark::DoNotOptimize(conv.grey().data());
  }
  state.counters["bytes"] = static_cast<double>(bytes.size());
}
BENCHMARK(BM_CameraFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
