/* Minimal PFM (portable float map) reading and writing for the temc examples.
 * 3-channel "PF" and 1-channel "Pf" files, either byte order, rows stored bottom-up. */
#ifndef TEMC_EXAMPLE_PFM_H
#define TEMC_EXAMPLE_PFM_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  int width, height, channels;
  float* data; /* top-down rows, interleaved channels */
} Image;

static inline int host_is_little_endian(void) {
  const uint16_t one = 1;
  return *(const uint8_t*)&one == 1;
}

static inline void swap4(float* v) {
  uint8_t* b = (uint8_t*)v;
  uint8_t t = b[0]; b[0] = b[3]; b[3] = t;
  t = b[1]; b[1] = b[2]; b[2] = t;
}

/* Returns 0 on success; prints the reason and returns -1 otherwise. */
static inline int pfm_read(const char* path, Image* img) {
  FILE* f = fopen(path, "rb");
  char magic[3] = {0};
  double scale;
  size_t n, row, y, i;
  if (!f) { fprintf(stderr, "%s: cannot open\n", path); return -1; }
  if (fscanf(f, "%2s %d %d %lf", magic, &img->width, &img->height, &scale) != 4 || fgetc(f) == EOF ||
      (strcmp(magic, "PF") != 0 && strcmp(magic, "Pf") != 0) || img->width <= 0 || img->height <= 0 ||
      img->width > 65536 || img->height > 65536) {
    fprintf(stderr, "%s: not a PFM file\n", path); fclose(f); return -1;
  }
  img->channels = magic[1] == 'F' ? 3 : 1;
  row = (size_t)img->width * img->channels;
  n = row * img->height;
  img->data = (float*)malloc(n * sizeof(float));
  if (!img->data) { fclose(f); return -1; }
  for (y = 0; y < (size_t)img->height; ++y) {
    float* dst = img->data + ((size_t)img->height - 1 - y) * row;
    if (fread(dst, sizeof(float), row, f) != row) {
      fprintf(stderr, "%s: truncated\n", path); free(img->data); fclose(f); return -1;
    }
  }
  fclose(f);
  if ((scale < 0) != host_is_little_endian())
    for (i = 0; i < n; ++i) swap4(&img->data[i]);
  return 0;
}

static inline int pfm_write(const char* path, const Image* img) {
  FILE* f = fopen(path, "wb");
  size_t row = (size_t)img->width * img->channels, y;
  if (!f) { fprintf(stderr, "%s: cannot create\n", path); return -1; }
  fprintf(f, "%s\n%d %d\n%s\n", img->channels == 3 ? "PF" : "Pf", img->width, img->height,
          host_is_little_endian() ? "-1.0" : "1.0");
  for (y = 0; y < (size_t)img->height; ++y)
    if (fwrite(img->data + ((size_t)img->height - 1 - y) * row, sizeof(float), row, f) != row) {
      fclose(f); return -1;
    }
  return fclose(f) == 0 ? 0 : -1;
}

static inline void* read_file(const char* path, size_t* size) {
  FILE* f = fopen(path, "rb");
  void* buf;
  long n;
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  n = ftell(f);
  fseek(f, 0, SEEK_SET);
  buf = n > 0 ? malloc((size_t)n) : NULL;
  if (buf && fread(buf, 1, (size_t)n, f) != (size_t)n) { free(buf); buf = NULL; }
  fclose(f);
  *size = (size_t)n;
  return buf;
}

#endif
