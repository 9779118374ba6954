// OIDN's checks at commit, through the C++ wrapper (temc.hpp) as an oidn.hpp client sees
// them: each misconfigured "RT" filter fails filter.commit() with Error::InvalidOperation
// and OIDN's message (core/unet_filter.cpp), execute then refuses to run and leaves the
// output untouched, and fixing the configuration makes commit and execute succeed. Also
// OIDN's committed-device rule for new filters and buffers, and OIDN 2.5's semaphore calls
// (SemaphoreRef, DeviceRef::newSemaphore, signal/waitSemaphore(s)Async) on the CPU device.
//   commit_checks          (exit status 0 when every check holds)
#include "temc.hpp"

#include <cstdio>
#include <cstring>
#include <functional>
#include <vector>

namespace {

const size_t W = 24, H = 16;
int failures = 0;

// Checks the device's first unqueried error: its code and the start of its message.
void expectError(temc::DeviceRef& device, temc::Error code, const char* prefix,
                 const char* what) {
  const char* message = nullptr;
  temc::Error got = device.getError(message);
  bool ok = got == code;
  if (prefix && (!message || std::strncmp(message, prefix, std::strlen(prefix)) != 0))
    ok = false;
  if (!ok) {
    std::fprintf(stderr, "FAIL %s: error %d (\"%s\"), expected %d (\"%s...\")\n", what,
                 static_cast<int>(got), message ? message : "", static_cast<int>(code),
                 prefix ? prefix : "");
    ++failures;
  }
  while (device.getError() != temc::Error::None) {
  }
}

struct Images {
  std::vector<float> color = std::vector<float>(W * H * 3, 0.5f);
  std::vector<float> albedo = std::vector<float>(W * H * 3, 0.7f);
  std::vector<float> normal = std::vector<float>(W * H * 3, 0.0f);
  std::vector<float> output = std::vector<float>(W * H * 4, -7.0f);
};

// Builds an "RT" filter with `setup`, commits it and expects OIDN's error; then checks
// that execute refuses the uncommitted filter without writing the output.
void refused(temc::DeviceRef& device, const char* prefix, const char* what,
             const std::function<void(temc::FilterRef&, Images&)>& setup) {
  Images im;
  temc::FilterRef filter = device.newFilter("RT");
  filter.set("quality", temc::Quality::Fast);
  setup(filter, im);
  filter.commit();
  expectError(device, temc::Error::InvalidOperation, prefix, what);
  filter.execute();
  expectError(device, temc::Error::InvalidOperation, nullptr, what);
  for (float v : im.output)
    if (v != -7.0f) {
      std::fprintf(stderr, "FAIL %s: output written after a failed commit\n", what);
      ++failures;
      break;
    }
}

}  // namespace

int main() {
  temc::DeviceRef device = temc::newDevice(temc::DeviceType::CPU);
  device.commit();
  expectError(device, temc::Error::None, nullptr, "device");
  using F = temc::FilterRef;
  using temc::Format;

  refused(device, "input image not specified", "no input", [](F& f, Images& im) {
    f.setImage("output", im.output.data(), Format::Float3, W, H);
  });
  refused(device, "output image not specified", "no output", [](F& f, Images& im) {
    f.setImage("color", im.color.data(), Format::Float3, W, H);
  });
  refused(device, "unsupported input image format", "2-channel colour", [](F& f, Images& im) {
    f.setImage("color", im.color.data(), Format::Float2, W, H);
    f.setImage("output", im.output.data(), Format::Float3, W, H);
  });
  refused(device, "unsupported output image format", "1-channel output", [](F& f, Images& im) {
    f.setImage("color", im.color.data(), Format::Float3, W, H);
    f.setImage("output", im.output.data(), Format::Float, W, H);
  });
  refused(device, "input/output image channel count mismatch", "3 in, 4 out",
          [](F& f, Images& im) {
            f.setImage("color", im.color.data(), Format::Float3, W, H);
            f.setImage("output", im.output.data(), Format::Float4, W, H);
          });
  refused(device, "image size mismatch", "albedo smaller", [](F& f, Images& im) {
    f.setImage("color", im.color.data(), Format::Float3, W, H);
    f.setImage("albedo", im.albedo.data(), Format::Float3, W - 1, H);
    f.setImage("output", im.output.data(), Format::Float3, W, H);
  });
  refused(device, "image size mismatch", "output smaller", [](F& f, Images& im) {
    f.setImage("color", im.color.data(), Format::Float3, W, H);
    f.setImage("output", im.output.data(), Format::Float3, W, H - 1);
  });
  refused(device, "hdr and srgb modes cannot be enabled at the same time", "hdr with srgb",
          [](F& f, Images& im) {
            f.setImage("color", im.color.data(), Format::Float3, W, H);
            f.setImage("output", im.output.data(), Format::Float3, W, H);
            f.set("hdr", true);
            f.set("srgb", true);
          });
  refused(device, "invalid combination of input features", "aux without colour",
          [](F& f, Images& im) {
            f.setImage("albedo", im.albedo.data(), Format::Float3, W, H);
            f.setImage("normal", im.normal.data(), Format::Float3, W, H);
            f.setImage("output", im.output.data(), Format::Float3, W, H);
          });
  refused(device, "hdr mode is not supported for albedo filtering", "hdr albedo prefilter",
          [](F& f, Images& im) {
            f.setImage("albedo", im.albedo.data(), Format::Float3, W, H);
            f.setImage("output", im.output.data(), Format::Float3, W, H);
            f.set("hdr", true);
          });

  // "directional" (RTLightmap) is refused when set: temc has no directional model.
  {
    temc::FilterRef lightmap = device.newFilter("RTLightmap");
    lightmap.set("directional", true);
    expectError(device, temc::Error::InvalidArgument, nullptr, "directional lightmap");
  }

  // Fixed, the same filter commits and runs; half and float of equal channel count mix.
  {
    Images im;
    std::vector<unsigned short> halfColor(W * H * 3, 0x3800);  // 0.5 in binary16
    temc::FilterRef filter = device.newFilter("RT");
    filter.set("quality", temc::Quality::Fast);
    filter.setImage("color", halfColor.data(), Format::Half3, W, H);
    filter.setImage("albedo", im.albedo.data(), Format::Float3, W - 1, H);
    filter.setImage("output", im.output.data(), Format::Float3, W, H);
    filter.commit();
    expectError(device, temc::Error::InvalidOperation, "image size mismatch", "before the fix");
    filter.setImage("albedo", im.albedo.data(), Format::Float3, W, H);
    filter.commit();
    filter.execute();
    expectError(device, temc::Error::None, nullptr, "after the fix");
    if (!(im.output[0] > 0.0f && im.output[0] < 2.0f)) {
      std::fprintf(stderr, "FAIL after the fix: output %g\n", im.output[0]);
      ++failures;
    }
  }

  // OIDN wants a committed device before buffers and filters (oidnTest's "single filter"
  // checks it): InvalidOperation, and again after a change that needs another commit.
  {
    temc::DeviceRef fresh = temc::newDevice(temc::DeviceType::CPU);
    if (fresh.newFilter("RT") || fresh.newBuffer(64)) {
      std::fprintf(stderr, "FAIL uncommitted device: a filter or buffer was made\n");
      ++failures;
    }
    expectError(fresh, temc::Error::InvalidOperation, "changes to the device are not committed",
                "filter on an uncommitted device");
    fresh.commit();
    if (!fresh.newFilter("RT") || !fresh.newBuffer(64)) {
      std::fprintf(stderr, "FAIL committed device: no filter or buffer\n");
      ++failures;
    }
    expectError(fresh, temc::Error::None, nullptr, "filter on the committed device");
    fresh.set("numThreads", 1);
    if (fresh.newFilter("RT")) {
      std::fprintf(stderr, "FAIL changed device: a filter was made before the recommit\n");
      ++failures;
    }
    expectError(fresh, temc::Error::InvalidOperation, "changes to the device are not committed",
                "filter after numThreads");
  }

  // OIDN 2.5's semaphores through the wrapper, as a Vulkan/D3D interop client calls them:
  // the CPU device imports none, so every call fails as OIDN's CPU device makes it fail.
  {
    using temc::ExternalSemaphoreTypeFlag;
    const temc::ExternalSemaphoreTypeFlags types =
        device.get<temc::ExternalSemaphoreTypeFlags>("externalSemaphoreTypes");
    expectError(device, temc::Error::None, nullptr, "externalSemaphoreTypes");
    if (types || (types & ExternalSemaphoreTypeFlag::TimelineSemaphoreFD)) {
      std::fprintf(stderr, "FAIL externalSemaphoreTypes is not empty\n");
      ++failures;
    }
    temc::SemaphoreRef timeline =
        device.newSemaphore(ExternalSemaphoreTypeFlag::TimelineSemaphoreFD, 3);
    expectError(device, temc::Error::InvalidArgument,
                "external semaphore type not supported by the device", "semaphore from FD");
    int handle = 0;
    temc::SemaphoreRef fence = device.newSemaphore(
        temc::ExternalSemaphoreTypeFlags(ExternalSemaphoreTypeFlag::D3D12Fence), &handle,
        nullptr);
    expectError(device, temc::Error::InvalidArgument,
                "external semaphore type not supported by the device", "semaphore from handle");
    if (timeline || fence) {
      std::fprintf(stderr, "FAIL a semaphore was imported\n");
      ++failures;
    }
    device.waitSemaphoreAsync(timeline, 1);
    expectError(device, temc::Error::InvalidOperation,
                "waiting on semaphores is not supported by the device", "waitSemaphoreAsync");
    device.signalSemaphoreAsync(timeline, 2);
    expectError(device, temc::Error::InvalidOperation,
                "signaling semaphores is not supported by the device", "signalSemaphoreAsync");
    device.waitSemaphoresAsync({timeline, fence}, {1, 2}, {10, 10});
    expectError(device, temc::Error::InvalidOperation, nullptr, "waitSemaphoresAsync");
    device.signalSemaphoresAsync({timeline, fence});
    expectError(device, temc::Error::InvalidOperation, nullptr, "signalSemaphoresAsync");
  }

  if (failures == 0) std::printf("commit checks: all hold\n");
  return failures == 0 ? 0 : 1;
}
