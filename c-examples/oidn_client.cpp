// A renderer's denoising pass written the way OIDN 2.x clients write it (Cycles' CPU
// denoiser, oidnDenoise), through oidn.hpp renamed: #include <OpenImageDenoise/oidn.hpp>
// became "temc.hpp", oidn:: became temc::, OIDN_ became TEMC_. Nothing else is changed:
// device buffers, an "RT" filter, aux prefiltering, an error callback, a progress monitor,
// asynchronous execution and sync (a pass queued end to end, checked against the blocking
// one).
//   oidn_client            (exit status 0 when the pass ran without errors)
#include "temc.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

#if TEMC_VERSION_MAJOR < 2
#error "this client needs the 2.x API (buffers, executeAsync)"
#endif

namespace {

int errors = 0;

void onError(void* userPtr, temc::Error code, const char* message) {
  (void)userPtr;
  if (code != temc::Error::None) {
    std::fprintf(stderr, "denoiser error %d: %s\n", static_cast<int>(code), message);
    ++errors;
  }
}

struct Progress {
  int calls = 0;
  double last = 0.0;
};

bool onProgress(void* userPtr, double n) {
  Progress* p = static_cast<Progress*>(userPtr);
  ++p->calls;
  p->last = n;
  return true;  // keep going
}

// A pass of `w` x `h` RGB floats: a gradient with speckle (colour), two materials
// (albedo) and two facing directions (normal), with Monte Carlo-like noise on the aux.
void renderPasses(int w, int h, std::vector<float>& color, std::vector<float>& albedo,
                  std::vector<float>& albedoClean, std::vector<float>& normal) {
  color.resize(size_t(w) * h * 3);
  albedo.resize(color.size());
  albedoClean.resize(color.size());
  normal.resize(color.size());
  unsigned seed = 12345u;
  auto rnd = [&seed]() {
    seed = seed * 1664525u + 1013904223u;
    return float(seed >> 8) / float(1u << 24) - 0.5f;
  };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      size_t i = (size_t(y) * w + x) * 3;
      bool left = x < w / 2;
      for (int c = 0; c < 3; ++c) {
        albedoClean[i + c] = left ? (c == 0 ? 0.8f : 0.2f) : (c == 2 ? 0.7f : 0.3f);
        albedo[i + c] = albedoClean[i + c] + 0.15f * rnd();
        color[i + c] = albedoClean[i + c] * (0.5f + 0.5f * float(y) / h) * (1.0f + rnd());
        normal[i + c] = c == 2 ? 1.0f : (left && c == 0 ? 0.3f : 0.0f) + 0.1f * rnd();
      }
    }
}

double relMSE(const float* x, const std::vector<float>& ref) {
  double sum = 0.0;
  for (size_t i = 0; i < ref.size(); ++i) {
    double d = double(x[i]) - ref[i];
    sum += d * d / (double(ref[i]) * ref[i] + 0.01);
  }
  return sum / double(ref.size());
}

// The beauty pass again, queued end to end: the colour written into a fresh buffer, the
// filter executed and the output read back, all Async, and the filter released before the
// one sync. The device runs them in order, so the result equals the blocking pass's.
bool queuedPassMatches(temc::DeviceRef& device, int w, int h, const std::vector<float>& color,
                       temc::BufferRef& albedoBuf, temc::BufferRef& normalBuf,
                       const std::vector<float>& expected) {
  const size_t bytes = color.size() * sizeof(float);
  temc::BufferRef colorIn = device.newBuffer(bytes);
  temc::BufferRef out = device.newBuffer(bytes);
  temc::FilterRef filter = device.newFilter("RT");
  filter.setImage("color", colorIn, temc::Format::Float3, w, h);
  filter.setImage("albedo", albedoBuf, temc::Format::Float3, w, h);
  filter.setImage("normal", normalBuf, temc::Format::Float3, w, h);
  filter.setImage("output", out, temc::Format::Float3, w, h);
  filter.set("hdr", true);
  filter.set("cleanAux", true);
  filter.set("quality", temc::Quality::Balanced);
  filter.commit();
  std::vector<float> readBack(color.size(), -1.0f);
  colorIn.writeAsync(0, bytes, color.data());
  filter.executeAsync();
  out.readAsync(0, bytes, readBack.data());
  filter.release();  // the queued execution holds the filter until it has run
  device.sync();
  return device.getError() == temc::Error::None && readBack == expected;
}

}  // namespace

int main() {
  const int width = 64, height = 48;
  const size_t bytes = size_t(width) * height * 3 * sizeof(float);
  std::vector<float> color, albedo, albedoClean, normal;
  renderPasses(width, height, color, albedo, albedoClean, normal);

  temc::DeviceRef device = temc::newDevice(temc::DeviceType::CPU);
  if (!device) {
    const char* message = nullptr;
    temc::getError(message);
    std::fprintf(stderr, "no device: %s\n", message ? message : "?");
    return 1;
  }
  device.setErrorFunction(onError);
  device.set("setAffinity", false);
  device.set("verbose", 0);
  device.commit();
  std::printf("denoiser API %d.%d (%s)\n", device.get<int>("versionMajor"),
              device.get<int>("versionMinor"), TEMC_VERSION_STRING);

  // Device buffers, filled by the "renderer".
  temc::BufferRef colorBuf = device.newBuffer(bytes);
  temc::BufferRef albedoBuf = device.newBuffer(bytes);
  temc::BufferRef normalBuf = device.newBuffer(bytes);
  colorBuf.write(0, bytes, color.data());
  albedoBuf.writeAsync(0, bytes, albedo.data());
  std::memcpy(normalBuf.getData(), normal.data(), bytes);
  device.sync();

  // Prefilter the noisy albedo and normal in place, as Cycles does before the beauty pass.
  const char* auxNames[2] = {"albedo", "normal"};
  temc::BufferRef* auxBufs[2] = {&albedoBuf, &normalBuf};
  for (int k = 0; k < 2; ++k) {
    temc::FilterRef pre = device.newFilter("RT");
    pre.setImage(auxNames[k], *auxBufs[k], temc::Format::Float3, width, height);
    pre.setImage("output", *auxBufs[k], temc::Format::Float3, width, height);
    pre.set("quality", temc::Quality::High);
    pre.commit();
    pre.execute();
  }
  double before = relMSE(albedo.data(), albedoClean);
  double after = relMSE(static_cast<const float*>(albedoBuf.getData()), albedoClean);
  std::printf("albedo prefilter: RelMSE %.5f -> %.5f\n", before, after);
  if (!(after < before)) {
    std::fprintf(stderr, "prefiltering did not reduce the albedo error\n");
    return 1;
  }

  // The beauty pass, with clean aux, interleaved strides as a renderer's buffers have.
  temc::FilterRef filter = device.newFilter("RT");
  filter.setImage("color", colorBuf, temc::Format::Float3, width, height, 0,
                  3 * sizeof(float), width * 3 * sizeof(float));
  filter.setImage("albedo", albedoBuf, temc::Format::Float3, width, height);
  filter.setImage("normal", normalBuf, temc::Format::Float3, width, height);
  std::vector<float> output(size_t(width) * height * 3, -1.0f);
  filter.setImage("output", output.data(), temc::Format::Float3, width, height);
  filter.set("hdr", true);
  filter.set("srgb", false);
  filter.set("cleanAux", true);
  filter.set("quality", temc::Quality::Balanced);
  Progress progress;
  filter.setProgressMonitorFunction(onProgress, &progress);
  filter.commit();
  filter.executeAsync();
  device.sync();

  const char* message = nullptr;
  if (device.getError(message) != temc::Error::None) {
    std::fprintf(stderr, "denoising failed: %s\n", message);
    return 1;
  }
  if (errors) return 1;
  for (size_t i = 0; i < output.size(); ++i)
    if (!std::isfinite(output[i]) || output[i] < 0.0f) {
      std::fprintf(stderr, "bad output value at %zu\n", i);
      return 1;
    }
  if (!queuedPassMatches(device, width, height, color, albedoBuf, normalBuf, output)) {
    std::fprintf(stderr, "the queued pass differs from the blocking one\n");
    return 1;
  }
  if (progress.calls == 0 || progress.last != 1.0) {
    std::fprintf(stderr, "progress monitor: %d calls, last %g\n", progress.calls, progress.last);
    return 1;
  }
  std::printf("quality %d, alignment %d, overlap %d, hdr %d\n",
              static_cast<int>(filter.get<temc::Quality>("quality")),
              filter.get<int>("alignment"), filter.get<int>("overlap"),
              filter.get<bool>("hdr") ? 1 : 0);

  // GPU selection as renderers probe it: refused, with UnsupportedHardware.
  if (temc::isCUDADeviceSupported(0)) return 1;
  temc::DeviceRef gpu = temc::newDevice(temc::DeviceType::CUDA);
  if (gpu || temc::getError() != temc::Error::UnsupportedHardware) {
    std::fprintf(stderr, "a GPU device type must be UnsupportedHardware\n");
    return 1;
  }
  for (int i = 0; i < temc::getNumPhysicalDevices(); ++i) {
    temc::PhysicalDeviceRef pd(i);
    std::printf("physical device %d: %s (type %d)\n", i,
                pd.get<std::string>("name").c_str(),
                static_cast<int>(pd.get<temc::DeviceType>("type")));
  }
  std::printf("oidn_client: ok\n");
  return 0;
}
