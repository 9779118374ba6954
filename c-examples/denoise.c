/* Denoise a PFM image with temc's C API, checking every error.
 *
 *   denoise COLOR.pfm [-a ALBEDO.pfm] [-n NORMAL.pfm] [-q fast|balanced|high] [-m MODEL.onnx]
 *           -o OUTPUT.pfm
 *
 * Without -m the library's built-in TEMC-2 model for the quality mode runs; MODEL.onnx is
 * any temc model file. */
#include <stdio.h>
#include <string.h>

#include "temc.h"
#include "pfm.h"

static int check(TEMCDevice device, const char* what) {
  const char* message;
  TEMCError err = temcGetDeviceError(device, &message);
  if (err != TEMC_ERROR_NONE) {
    fprintf(stderr, "temc error %u during %s: %s\n", (unsigned)err, what, message ? message : "");
    return -1;
  }
  return 0;
}

int main(int argc, char** argv) {
  const char *model_path = NULL, *color_path = NULL, *albedo_path = NULL, *normal_path = NULL,
             *out_path = NULL, *quality = "balanced";
  Image color = {0}, albedo = {0}, normal = {0}, output = {0};
  void* weights = NULL;
  size_t weights_size = 0;
  TEMCDevice device;
  TEMCFilter filter;
  int i, rc = 1;

  for (i = 1; i < argc; ++i) {
    if (!strcmp(argv[i], "-a") && i + 1 < argc) albedo_path = argv[++i];
    else if (!strcmp(argv[i], "-n") && i + 1 < argc) normal_path = argv[++i];
    else if (!strcmp(argv[i], "-o") && i + 1 < argc) out_path = argv[++i];
    else if (!strcmp(argv[i], "-m") && i + 1 < argc) model_path = argv[++i];
    else if (!strcmp(argv[i], "-q") && i + 1 < argc) quality = argv[++i];
    else if (!color_path) color_path = argv[i];
    else { fprintf(stderr, "unexpected argument %s\n", argv[i]); return 2; }
  }
  if (!color_path || !out_path) {
    fprintf(stderr,
            "usage: %s COLOR.pfm [-a ALBEDO.pfm] [-n NORMAL.pfm] [-q fast|balanced|high] "
            "[-m MODEL.onnx] -o OUT.pfm\n", argv[0]);
    return 2;
  }
  if (strcmp(quality, "fast") && strcmp(quality, "balanced") && strcmp(quality, "high")) {
    fprintf(stderr, "unknown quality %s\n", quality);
    return 2;
  }
  if (model_path) {
    weights = read_file(model_path, &weights_size);
    if (!weights) { fprintf(stderr, "%s: cannot read\n", model_path); return 1; }
  }
  if (pfm_read(color_path, &color) || color.channels != 3) return 1;
  if (albedo_path && pfm_read(albedo_path, &albedo)) return 1;
  if (normal_path && pfm_read(normal_path, &normal)) return 1;

  device = temcNewDevice(TEMC_DEVICE_TYPE_DEFAULT);
  if (!device) { check(NULL, "device creation"); return 1; }
  temcCommitDevice(device);
  if (check(device, "device commit")) goto done_device;

  filter = temcNewFilter(device, "TEMC2");
  if (check(device, "filter creation")) goto done_device;
  output = color;
  output.data = (float*)malloc(sizeof(float) * 3 * color.width * color.height);
  if (weights) temcSetSharedFilterData(filter, "weights", weights, weights_size);
  temcSetFilterInt(filter, "quality",
                   !strcmp(quality, "fast") ? TEMC_QUALITY_FAST
                   : !strcmp(quality, "high") ? TEMC_QUALITY_HIGH : TEMC_QUALITY_BALANCED);
  temcSetSharedFilterImage(filter, "color", color.data, TEMC_FORMAT_FLOAT3, color.width, color.height, 0, 0, 0);
  if (albedo.data)
    temcSetSharedFilterImage(filter, "albedo", albedo.data, TEMC_FORMAT_FLOAT3, albedo.width, albedo.height, 0, 0, 0);
  if (normal.data)
    temcSetSharedFilterImage(filter, "normal", normal.data, TEMC_FORMAT_FLOAT3, normal.width, normal.height, 0, 0, 0);
  temcSetSharedFilterImage(filter, "output", output.data, TEMC_FORMAT_FLOAT3, color.width, color.height, 0, 0, 0);
  temcSetFilterBool(filter, "hdr", true);
  if (check(device, "filter set-up")) goto done_filter;
  temcCommitFilter(filter);
  if (check(device, "filter commit")) goto done_filter;
  temcExecuteFilter(filter);
  if (check(device, "filter execution")) goto done_filter;
  if (pfm_write(out_path, &output) == 0) rc = 0;

done_filter:
  temcReleaseFilter(filter);
done_device:
  temcReleaseDevice(device);
  free(weights);
  free(color.data);
  free(albedo.data);
  free(normal.data);
  free(output.data);
  return rc;
}
