// temc from C++: the C header is usable as is (extern "C"), here wrapped in RAII handles.
//   denoise_cpp MODEL.onnx      denoises a synthetic noisy gradient in place.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "temc.h"

namespace {

struct DeviceDeleter { void operator()(TEMCDeviceImpl* d) const { temcReleaseDevice(d); } };
struct FilterDeleter { void operator()(TEMCFilterImpl* f) const { temcReleaseFilter(f); } };

void check(TEMCDevice device) {
  const char* message = nullptr;
  if (temcGetDeviceError(device, &message) != TEMC_ERROR_NONE)
    throw std::runtime_error(message ? message : "temc error");
}

}  // namespace

int main(int argc, char** argv) try {
  if (argc != 2) { std::fprintf(stderr, "usage: %s MODEL.onnx\n", argv[0]); return 2; }
  std::ifstream in(argv[1], std::ios::binary);
  std::vector<char> weights((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (weights.empty()) throw std::runtime_error("cannot read the model");

  const int w = 96, h = 64;
  std::vector<float> image(w * h * 3);
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> noise(0.5f, 1.5f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) image[(y * w + x) * 3 + c] = (0.2f + 0.01f * x * (c + 1)) * noise(rng);

  std::unique_ptr<TEMCDeviceImpl, DeviceDeleter> device(temcNewDevice(TEMC_DEVICE_TYPE_DEFAULT));
  check(nullptr);
  temcCommitDevice(device.get());
  check(device.get());
  std::unique_ptr<TEMCFilterImpl, FilterDeleter> filter(temcNewFilter(device.get(), "TEMC2"));
  temcSetSharedFilterData(filter.get(), "weights", weights.data(), weights.size());
  temcSetSharedFilterImage(filter.get(), "color", image.data(), TEMC_FORMAT_FLOAT3, w, h, 0, 0, 0);
  temcSetSharedFilterImage(filter.get(), "output", image.data(), TEMC_FORMAT_FLOAT3, w, h, 0, 0, 0);
  temcCommitFilter(filter.get());
  temcExecuteFilter(filter.get());
  check(device.get());
  double sum = 0;
  for (float v : image) {
    if (!std::isfinite(v)) throw std::runtime_error("non-finite output");
    sum += v;
  }
  std::printf("denoised %dx%d in place, mean %.6f\n", w, h, sum / image.size());
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
