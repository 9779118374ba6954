/* Every misuse of temc's C API gives the documented error code and writes nothing.
 *   misuse MODEL.onnx        (exit status 0 when every check passes) */
#include <math.h>
#include <stdio.h>
#include <stdint.h>
#include <string.h>

#include "temc.h"
#include "pfm.h"

static int failures = 0;
static int callback_calls = 0;

#define EXPECT(dev, code, what)                                                        \
  do {                                                                                 \
    const char* msg = NULL;                                                            \
    TEMCError got = temcGetDeviceError((dev), &msg);                                   \
    if (got != (code)) {                                                               \
      fprintf(stderr, "FAIL %s: expected error %d, got %u (%s)\n", (what), (code),     \
              (unsigned)got, msg ? msg : "");                                          \
      ++failures;                                                                      \
    } else if ((code) != TEMC_ERROR_NONE && (!msg || !*msg)) {                         \
      fprintf(stderr, "FAIL %s: error without a message\n", (what));                   \
      ++failures;                                                                      \
    }                                                                                  \
  } while (0)

static void on_error(void* user, TEMCError code, const char* message) {
  (void)code; (void)message;
  ++*(int*)user;
}

static bool cancel_at_once(void* user, double n) {
  (void)user; (void)n;
  return false;
}

static int untouched(const float* v, size_t n) {
  size_t i;
  for (i = 0; i < n; ++i) if (v[i] != -7.0f) return 0;
  return 1;
}

int main(int argc, char** argv) {
  enum { W = 48, H = 40 };
  static float color[W * H * 3], out[W * H * 3], small[(W - 1) * H * 3];
  size_t weights_size = 0, i;
  void* weights;
  TEMCDevice dev;
  TEMCFilter f;

  if (argc != 2 || !(weights = read_file(argv[1], &weights_size))) {
    fprintf(stderr, "usage: %s MODEL.onnx\n", argv[0]);
    return 2;
  }
  for (i = 0; i < W * H * 3; ++i) color[i] = (float)(i % 17) / 17.0f;

  /* Devices. */
  if (temcNewDevice(99) != NULL) { fprintf(stderr, "FAIL: bad device type accepted\n"); ++failures; }
  EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "bad device type");
  EXPECT(NULL, TEMC_ERROR_NONE, "error cleared after query");
  temcCommitDevice(NULL);
  EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "NULL device");
  dev = temcNewDevice(TEMC_DEVICE_TYPE_CPU);
  temcSetDeviceErrorFunction(dev, on_error, &callback_calls);
  temcSetDeviceInt(dev, "numThreads", 2);
  temcSetDeviceInt(dev, "noSuchParam", 1);
  EXPECT(dev, TEMC_ERROR_NONE, "unknown device parameter (a warning, as in OIDN)");
  temcSetDeviceInt(dev, "numThreads", -1);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "negative thread count");

  /* As in OIDN, filters and buffers need a committed device. */
  if (temcNewFilter(dev, "TEMC2") != NULL) { fprintf(stderr, "FAIL: filter on an uncommitted device\n"); ++failures; }
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "filter on an uncommitted device");
  if (temcNewBuffer(dev, 64) != NULL) { fprintf(stderr, "FAIL: buffer on an uncommitted device\n"); ++failures; }
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "buffer on an uncommitted device");
  temcCommitDevice(dev);
  EXPECT(dev, TEMC_ERROR_NONE, "device commit");

  /* Filters. */
  if (temcNewFilter(dev, "NOPE") != NULL) { fprintf(stderr, "FAIL: unknown filter\n"); ++failures; }
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "unknown filter type");
  temcNewFilter(dev, NULL);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "NULL filter type");
  f = temcNewFilter(dev, "TEMC2");
  EXPECT(dev, TEMC_ERROR_NONE, "filter creation");

  temcSetSharedFilterImage(f, "colour", color, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  EXPECT(dev, TEMC_ERROR_NONE, "unknown image name (a warning, as in OIDN)");
  temcSetSharedFilterImage(f, "color", NULL, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "NULL image pointer");
  temcSetSharedFilterImage(f, "color", color, 77, W, H, 0, 0, 0);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "unknown format");
  temcSetSharedFilterImage(f, "color", color, TEMC_FORMAT_FLOAT3, 0, H, 0, 0, 0);
  EXPECT(dev, TEMC_ERROR_NONE, "zero width (an empty image, as in OIDN)");
  temcSetSharedFilterImage(f, "color", color, TEMC_FORMAT_FLOAT3, W, H, 0, 4, 0);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "pixel stride smaller than a pixel");
  temcSetSharedFilterImage(f, "color", color, TEMC_FORMAT_FLOAT3, SIZE_MAX, H, 0, 0, 0);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "huge width");
  temcSetSharedFilterImage(f, "color", color, TEMC_FORMAT_FLOAT3, W, H, 0, SIZE_MAX / 4, 0);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "overflowing stride");
  temcSetFilterInt(f, "quality", 3);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "unknown quality");
  temcSetFilterInt(f, "noSuchParam", 3);
  EXPECT(dev, TEMC_ERROR_NONE, "unknown int parameter (a warning)");
  temcSetFilterFloat(f, "inputScale", -1.0f);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "negative input scale");
  if (!isnan(temcGetFilterFloat(f, "inputScale"))) { fprintf(stderr, "FAIL: inputScale not automatic\n"); ++failures; }
  temcSetFilterFloat(f, "inputScale", 2.0f);
  if (temcGetFilterFloat(f, "inputScale") != 2.0f) { fprintf(stderr, "FAIL: inputScale not read back\n"); ++failures; }
  temcSetFilterFloat(f, "inputScale", NAN);
  temcGetFilterFloat(f, "noSuchParam");
  EXPECT(dev, TEMC_ERROR_NONE, "unknown float parameter (a warning)");
  temcSetFilterInt(f, "spectralBands", 0);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "zero spectral bands");
  temcSetFilterFloat(f, "spectralMin", -5.0f);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "negative wavelength");
  temcSetSharedFilterImage(f, "spectral", color, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "spectral image with a 3-channel format");
  temcUpdateFilterData(f, "weights");
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "update of unset weights");
  if (temcGetFilterInt(f, "maxMemoryMB") != 2048) { fprintf(stderr, "FAIL: default maxMemoryMB\n"); ++failures; }
  if (!temcGetFilterBool(f, "hdr")) { fprintf(stderr, "FAIL: hdr default\n"); ++failures; }
  temcSetSharedFilterData(f, "weights", NULL, 10);
  EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "NULL weights");

  /* Execute before commit, commit without weights, garbage weights. */
  memset(out, 0, sizeof out);
  for (i = 0; i < W * H * 3; ++i) out[i] = -7.0f;
  temcSetSharedFilterImage(f, "color", color, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  temcSetSharedFilterImage(f, "output", out, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  EXPECT(dev, TEMC_ERROR_NONE, "image set-up");
  temcExecuteFilter(f);
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "execute before commit");
  {
    /* Only TEMC2 has built-in models; a baseline needs "weights". */
    TEMCFilter g = temcNewFilter(dev, "DEMC");
    temcCommitFilter(g);
    EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "commit without weights");
    temcReleaseFilter(g);
  }
  temcSetSharedFilterData(f, "weights", color, sizeof color);
  temcCommitFilter(f);
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "garbage weights (at commit, as in OIDN)");
  if (!untouched(out, W * H * 3)) { fprintf(stderr, "FAIL: output written on error\n"); ++failures; }

  /* Missing output, mismatched sizes: commit fails (as in OIDN), execute then refuses
   * the uncommitted filter, and the output stays untouched. */
  temcSetSharedFilterData(f, "weights", weights, weights_size);
  temcUnsetFilterImage(f, "output");
  temcCommitFilter(f);
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "commit without output");
  temcExecuteFilter(f);
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "execute after a failed commit");
  for (i = 0; i < (W - 1) * H * 3; ++i) small[i] = -7.0f;
  temcSetSharedFilterImage(f, "output", small, TEMC_FORMAT_FLOAT3, W - 1, H, 0, 0, 0);
  temcCommitFilter(f);
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "size mismatch at commit");
  temcExecuteFilter(f);
  EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "execute after a size mismatch");
  if (!untouched(small, (W - 1) * H * 3)) { fprintf(stderr, "FAIL: output written on mismatch\n"); ++failures; }

  /* Cancellation leaves the output untouched; the filter still works afterwards. */
  temcSetSharedFilterImage(f, "output", out, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  temcSetFilterProgressMonitorFunction(f, cancel_at_once, NULL);
  temcCommitFilter(f);
  temcExecuteFilter(f);
  EXPECT(dev, TEMC_ERROR_CANCELLED, "cancelled by the progress monitor");
  if (!untouched(out, W * H * 3)) { fprintf(stderr, "FAIL: output written on cancel\n"); ++failures; }
  temcSetFilterProgressMonitorFunction(f, NULL, NULL);
  temcExecuteFilter(f);
  EXPECT(dev, TEMC_ERROR_NONE, "execute after cancel");
  for (i = 0; i < W * H * 3; ++i)
    if (!isfinite(out[i]) || out[i] < 0) { fprintf(stderr, "FAIL: bad output\n"); ++failures; break; }

  /* In place: output aliasing color. */
  temcSetSharedFilterImage(f, "output", color, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  temcCommitFilter(f);
  temcExecuteFilter(f);
  EXPECT(dev, TEMC_ERROR_NONE, "in-place execution");
  if (memcmp(color, out, sizeof out) != 0) { fprintf(stderr, "FAIL: in-place differs\n"); ++failures; }

  /* Retain and release; use after release is reported, not dereferenced. */
  temcRetainFilter(f);
  temcReleaseFilter(f);
  temcCommitFilter(f);
  EXPECT(dev, TEMC_ERROR_NONE, "filter alive while retained");
  temcReleaseFilter(f);
  temcCommitFilter(f);
  EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "filter used after release");
  temcReleaseFilter(f);
  EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "filter released twice");

  /* The calls OIDN 2.x added: buffers, physical devices, GPU types, async. */
  {
    float host[16];
    TEMCBuffer b, stale;
    TEMCDevice other;
    TEMCFilter g;
    size_t size = 99;
    for (i = 0; i < 16; ++i) host[i] = (float)i;
    if (temcNewCUDADevice(NULL, NULL, 0) != NULL) { fprintf(stderr, "FAIL: CUDA device\n"); ++failures; }
    EXPECT(NULL, TEMC_ERROR_UNSUPPORTED_HARDWARE, "CUDA device");
    if (temcNewDevice(TEMC_DEVICE_TYPE_SYCL) != NULL) { fprintf(stderr, "FAIL: SYCL device\n"); ++failures; }
    EXPECT(NULL, TEMC_ERROR_UNSUPPORTED_HARDWARE, "SYCL device type");
    if (temcNewDeviceByID(1) != NULL) { fprintf(stderr, "FAIL: physical device 1\n"); ++failures; }
    EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "physical device 1");
    if (temcGetPhysicalDeviceData(0, "uuid", &size) != NULL || size != 0) { fprintf(stderr, "FAIL: CPU UUID\n"); ++failures; }
    EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "CPU has no UUID");
    if (temcNewBuffer(NULL, 64) != NULL) { fprintf(stderr, "FAIL: buffer without device\n"); ++failures; }
    EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "buffer on a NULL device");
    temcNewBufferWithStorage(dev, 64, 42);
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "unknown storage");
    temcNewSharedBuffer(dev, NULL, 64);
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "shared buffer over NULL");
    temcNewSharedBufferFromFD(dev, TEMC_EXTERNAL_MEMORY_TYPE_FLAG_OPAQUE_FD, 3, 64);
    EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "external memory on the CPU");
    /* OIDN 2.5's semaphores: the CPU device imports no type of them. */
    if (temcGetDeviceInt(dev, "externalSemaphoreTypes") != 0) { fprintf(stderr, "FAIL: semaphore types\n"); ++failures; }
    if (temcNewSharedSemaphoreFromFD(dev, TEMC_EXTERNAL_SEMAPHORE_TYPE_FLAG_OPAQUE_FD, 3) != NULL) { fprintf(stderr, "FAIL: semaphore\n"); ++failures; }
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "external semaphore on the CPU");
    temcSignalSemaphoresAsync(dev, NULL, NULL, 0);
    EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "signal semaphores on the CPU");
    temcReleaseSemaphore(NULL);
    EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "NULL semaphore");
    b = temcNewBuffer(dev, sizeof host);
    temcWriteBuffer(b, 8, sizeof host, host);
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "write past the end");
    temcReadBuffer(b, SIZE_MAX, 2, host);
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "overflowing read offset");
    temcReadBuffer(b, 0, 4, NULL);
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "read into NULL");
    g = temcNewFilter(dev, "RT");
    temcSetFilterImage(g, "color", b, TEMC_FORMAT_FLOAT3, 4, 4, 0, 0, 0);
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "image larger than its buffer");
    other = temcNewDevice(TEMC_DEVICE_TYPE_CPU);
    temcCommitDevice(other);
    stale = temcNewBuffer(other, sizeof host);
    temcSetFilterImage(g, "color", stale, TEMC_FORMAT_FLOAT, 4, 4, 0, 0, 0);
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "buffer of another device");
    temcReleaseBuffer(stale);
    temcReleaseDevice(other);
    temcGetBufferSize(stale);
    EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "buffer used after release");
    temcReleaseBuffer(stale);
    EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "buffer released twice");
    temcExecuteSYCLFilterAsync(g, NULL, 0, NULL);
    EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "SYCL execution on the CPU");
    temcExecuteFilterAsync(g);
    EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "async execute before commit");
    temcSyncDevice(dev);
    EXPECT(dev, TEMC_ERROR_NONE, "sync");
    /* Only albedo and no output: neither a prefilter nor a denoise. */
    temcSetSharedFilterImage(g, "albedo", color, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
    temcCommitFilter(g);
    EXPECT(dev, TEMC_ERROR_INVALID_OPERATION, "RT with albedo and no output");
    temcReleaseFilter(g);
    g = temcNewFilter(dev, "RTLightmap");
    temcSetFilterBool(g, "directional", true);
    EXPECT(dev, TEMC_ERROR_INVALID_ARGUMENT, "directional lightmap");
    temcReleaseFilter(g);
    temcReleaseBuffer(b);
  }

  if (callback_calls < 10) { fprintf(stderr, "FAIL: error callback called %d times\n", callback_calls); ++failures; }
  temcReleaseDevice(dev);
  temcCommitDevice(dev);
  EXPECT(NULL, TEMC_ERROR_INVALID_ARGUMENT, "device used after release");
  free(weights);
  if (failures) { fprintf(stderr, "%d check(s) failed\n", failures); return 1; }
  printf("misuse: all checks passed\n");
  return 0;
}
