/* The C example of OIDN 2.x's API documentation, as a renderer writes it (buffers owned
 * by the device, an "RT" filter), renamed to temc: oidn -> temc, OIDN_ -> TEMC_,
 * <OpenImageDenoise/oidn.h> -> "temc.h". Also a shared buffer over the caller's memory.
 *   buffers                (exit status 0 when every call succeeded) */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "temc.h"

#if TEMC_VERSION_MAJOR < 2
#error "the buffer API needs 2.x"
#endif

static int check(TEMCDevice device, const char* what) {
  const char* message;
  if (temcGetDeviceError(device, &message) != TEMC_ERROR_NONE) {
    fprintf(stderr, "%s: %s\n", what, message);
    return 1;
  }
  return 0;
}

int main(void) {
  enum { W = 40, H = 30 };
  const size_t bytes = (size_t)W * H * 3 * sizeof(float);
  static float shared[W * H * 3];
  size_t i;
  float *colorPtr, *outputPtr;
  float readBack[3];
  TEMCDevice device;
  TEMCBuffer colorBuf, albedoBuf, outputBuf, sharedBuf;
  TEMCFilter filter;

  /* Create an Open Image Denoise device. */
  device = temcNewDevice(TEMC_DEVICE_TYPE_DEFAULT);
  temcCommitDevice(device);
  if (check(device, "device")) return 1;

  /* Create buffers for input/output images accessible by both host (CPU) and device. */
  colorBuf = temcNewBuffer(device, bytes);
  albedoBuf = temcNewBufferWithStorage(device, bytes, TEMC_STORAGE_MANAGED);
  outputBuf = temcNewBuffer(device, bytes);

  /* Create a filter for denoising a beauty (color) image using optional auxiliary images. */
  filter = temcNewFilter(device, "RT");
  temcSetFilterImage(filter, "color", colorBuf, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  temcSetFilterImage(filter, "albedo", albedoBuf, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  temcSetFilterImage(filter, "output", outputBuf, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  temcSetFilterBool(filter, "hdr", true);
  temcSetFilterInt(filter, "quality", TEMC_QUALITY_FAST); /* an interactive preview */
  temcCommitFilter(filter);
  if (check(device, "filter setup")) return 1;

  /* Fill the input image buffers. */
  colorPtr = (float*)temcGetBufferData(colorBuf);
  for (i = 0; i < W * H * 3; ++i) colorPtr[i] = 0.25f + (float)(i % 11) / 22.0f;
  {
    float albedo[W * H * 3];
    for (i = 0; i < W * H * 3; ++i) albedo[i] = 0.5f;
    temcWriteBuffer(albedoBuf, 0, bytes, albedo);
  }

  /* Filter the beauty image. */
  temcExecuteFilter(filter);
  if (check(device, "execute")) return 1;
  outputPtr = (float*)temcGetBufferData(outputBuf);
  for (i = 0; i < W * H * 3; ++i)
    if (!isfinite(outputPtr[i]) || outputPtr[i] < 0.0f) {
      fprintf(stderr, "bad output at %lu\n", (unsigned long)i);
      return 1;
    }
  temcReadBufferAsync(outputBuf, 0, sizeof readBack, readBack);
  temcSyncDevice(device);
  if (memcmp(readBack, outputPtr, sizeof readBack) != 0) {
    fprintf(stderr, "read back differs\n");
    return 1;
  }

  /* A shared buffer over the caller's memory, denoised in place. */
  memcpy(shared, colorPtr, bytes);
  sharedBuf = temcNewSharedBuffer(device, shared, bytes);
  if (temcGetBufferData(sharedBuf) != (void*)shared || temcGetBufferSize(sharedBuf) != bytes) {
    fprintf(stderr, "shared buffer does not wrap the caller's memory\n");
    return 1;
  }
  temcSetFilterImage(filter, "color", sharedBuf, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  temcSetFilterImage(filter, "output", sharedBuf, TEMC_FORMAT_FLOAT3, W, H, 0, 0, 0);
  temcCommitFilter(filter);
  temcExecuteFilterAsync(filter);
  temcSyncDevice(device);
  if (check(device, "in-place execute")) return 1;
  if (memcmp(shared, outputPtr, bytes) != 0) {
    fprintf(stderr, "in-place result differs from the buffer result\n");
    return 1;
  }

  /* Cleanup: the filter holds its buffers; the order of releases does not matter. */
  temcReleaseBuffer(colorBuf);
  temcReleaseBuffer(albedoBuf);
  temcReleaseBuffer(outputBuf);
  temcReleaseBuffer(sharedBuf);
  temcReleaseFilter(filter);
  temcReleaseDevice(device);
  if (check(NULL, "cleanup")) return 1;
  printf("buffers: ok\n");
  return 0;
}
