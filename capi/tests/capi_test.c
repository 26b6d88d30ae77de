/* The C ABI from C: round trips within the bound, windows equal crops, the golden files
 * decode to the Rust decoder's samples bit for bit, a file read through range-read
 * callbacks (vtz_open_reader) decodes as from memory, and bad input gives a code and a
 * message, never a crash. Built and run by capi/run-c-test.sh (CI: .ci/run).
 *
 *   capi_test GOLDEN_DIR TMP_DIR
 */
#include "vtz.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;
static int checks = 0;

#define CHECK(cond, ...)                                                   \
  do {                                                                     \
    checks++;                                                              \
    if (!(cond)) {                                                         \
      failures++;                                                          \
      fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__);                 \
      fprintf(stderr, __VA_ARGS__);                                        \
      fprintf(stderr, " (last error: %s)\n", vtz_last_error());           \
    }                                                                      \
  } while (0)

static unsigned char *read_file(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  unsigned char *b = malloc(n > 0 ? (size_t)n : 1);
  if (b && fread(b, 1, (size_t)n, f) != (size_t)n) {
    free(b);
    b = NULL;
  }
  fclose(f);
  *len = (size_t)n;
  return b;
}

/* A terrain of W x H int16 samples with a hole of nodata. */
enum { W = 300, H = 200 };
static const int16_t NODATA = -32768;

static void make_terrain(int16_t *z) {
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      double v = 800.0 + 400.0 * sin(x * 0.031) * cos(y * 0.047) + 3.0 * ((x * 7 + y * 13) % 11);
      int hole = (x - 60) * (x - 60) + (y - 50) * (y - 50) < 15 * 15;
      z[y * W + x] = hole ? NODATA : (int16_t)lround(v);
    }
}

/* A progress callback: counts calls, checks the fractions never decrease. */
struct progress {
  int calls;
  double last;
  int decreasing;
};
static void on_progress(double f, void *data) {
  struct progress *p = data;
  if (f < p->last) p->decreasing = 1;
  p->last = f;
  p->calls++;
}

static void test_round_trip_and_windows(void) {
  static int16_t src[W * H], dec[W * H], win[40 * 30];
  static double wide[W * H];
  make_terrain(src);
  VtzEncodeOptions o = vtz_encode_options_init();
  o.max_error = 1.0;
  o.has_nodata = 1;
  o.nodata = NODATA;
  o.has_geotransform = 1;
  double gt[6] = {-159.8, 1.0 / 1200, 0, 22.3, 0, -1.0 / 1200};
  memcpy(o.geotransform, gt, sizeof gt);
  o.epsg = 4326;
  o.gdal_metadata = "<GDALMetadata><Item name=\"UNITTYPE\" sample=\"0\" role=\"unittype\">m</Item></GDALMetadata>";
  struct progress prog = {0, 0.0, 0};
  o.progress = on_progress;
  o.progress_data = &prog;
  uint8_t *bytes = NULL;
  size_t len = 0;
  int rc = vtz_encode(src, VTZ_I16, W, H, &o, &bytes, &len);
  CHECK(rc == VTZ_OK && bytes && len > 0, "encode: rc %d", rc);
  CHECK(prog.calls >= 2 && prog.last == 1.0 && !prog.decreasing,
        "progress: %d calls, last %g, decreasing %d", prog.calls, prog.last, prog.decreasing);
  if (rc != VTZ_OK) return;

  VtzFile *f = NULL;
  rc = vtz_open_memory(bytes, len, NULL, &f);
  CHECK(rc == VTZ_OK && f, "open_memory: rc %d", rc);
  if (!f) return;
  VtzInfo info;
  CHECK(vtz_get_info(f, &info) == VTZ_OK, "get_info");
  CHECK(info.width == W && info.height == H, "size %ux%u", info.width, info.height);
  CHECK(info.sample_type == VTZ_I16, "sample type %d", info.sample_type);
  CHECK(info.has_nodata && info.nodata == NODATA, "nodata");
  CHECK(info.has_geotransform && memcmp(info.geotransform, gt, sizeof gt) == 0, "geotransform");
  CHECK(info.epsg == 4326, "epsg %u", info.epsg);
  CHECK(info.max_error > 0 && info.max_error <= 1.0, "stored max error %g", info.max_error);
  CHECK(info.tiled == 0 && info.tile_cols == 1, "untiled");
  CHECK(info.file_bytes == len, "file bytes");
  char crs[8192];
  size_t need = vtz_get_crs(f, NULL, 0);
  CHECK(need > 1 && need <= sizeof crs, "crs length %zu", need);
  CHECK(vtz_get_crs(f, crs, sizeof crs) == need && strstr(crs, "WGS 84"), "crs text: %.60s", crs);
  size_t ntiff = vtz_get_georef_geotiff(f, NULL, 0);
  uint8_t tiff[4096];
  CHECK(ntiff > 8 && ntiff <= sizeof tiff && vtz_get_georef_geotiff(f, tiff, sizeof tiff) == ntiff &&
            memcmp(tiff, "II*", 3) == 0,
        "the georeferencing as a GeoTIFF: %zu bytes", ntiff);
  char meta[512];
  /* Lossy: the metadata comes back without statistics, the rest byte for byte. */
  CHECK(vtz_get_gdal_metadata(f, meta, sizeof meta) == strlen(o.gdal_metadata) + 1 &&
            strcmp(meta, o.gdal_metadata) == 0,
        "gdal metadata");

  rc = vtz_read(f, 0, 0, W, H, VTZ_I16, dec, sizeof dec, 0);
  CHECK(rc == VTZ_OK, "read: rc %d", rc);
  int worst = 0, nodata_ok = 1;
  for (int i = 0; i < W * H; i++) {
    if (src[i] == NODATA) {
      nodata_ok &= dec[i] == NODATA;
    } else {
      int d = abs((int)dec[i] - (int)src[i]);
      if (d > worst) worst = d;
    }
  }
  CHECK(worst <= 1, "max error %d over the bound 1", worst);
  CHECK(nodata_ok, "nodata samples decode as nodata");

  /* A window is the crop of the full decode, on 1 and 2 threads. */
  for (uint32_t threads = 1; threads <= 2; threads++) {
    rc = vtz_read(f, 37, 41, 40, 30, VTZ_I16, win, sizeof win, threads);
    CHECK(rc == VTZ_OK, "window read");
    int same = 1;
    for (int y = 0; y < 30; y++)
      for (int x = 0; x < 40; x++) same &= win[y * 40 + x] == dec[(41 + y) * W + 37 + x];
    CHECK(same, "window (37, 41, 40, 30) on %u threads is the crop", threads);
  }
  /* Overview K of an untiled file: the full decode at every 2^K-th row and column; level 0
     is vtz_read; a window is in the overview's samples; levels past 30 and windows outside
     are errors. */
  for (uint32_t k = 0; k <= 3; k++) {
    uint32_t s = 1u << k, ow = (W + s - 1) / s, oh = (H + s - 1) / s;
    rc = vtz_read_overview(f, k, 0, 0, ow, oh, VTZ_I16, wide, (size_t)ow * oh * 2, 0);
    int16_t *ov = (int16_t *)wide;
    int eq = rc == VTZ_OK;
    for (uint32_t y = 0; eq && y < oh; y++)
      for (uint32_t x = 0; x < ow; x++) eq &= ov[y * ow + x] == dec[y * s * W + x * s];
    CHECK(eq, "overview %u (%ux%u) is the full decode at every %u-th sample: rc %d", k, ow, oh, s, rc);
  }
  rc = vtz_read_overview(f, 2, 3, 4, 5, 6, VTZ_I16, win, 5 * 6 * 2, 1);
  int eq2 = rc == VTZ_OK;
  for (int y = 0; eq2 && y < 6; y++)
    for (int x = 0; x < 5; x++) eq2 &= win[y * 5 + x] == dec[(4 + y) * 4 * W + (3 + x) * 4];
  CHECK(eq2, "a window of overview 2 is its crop: rc %d", rc);
  rc = vtz_read_overview(f, 31, 0, 0, 1, 1, VTZ_I16, win, 2, 0);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT && strstr(vtz_last_error(), "1..=30"), "overview 31: rc %d", rc);
  rc = vtz_read_overview(f, 1, (W + 1) / 2, 0, 1, 1, VTZ_I16, win, 2, 0);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT, "a window outside overview 1: rc %d", rc);
  /* A wider type gets the same values. */
  CHECK(vtz_read(f, 0, 0, W, H, VTZ_F64, wide, sizeof wide, 0) == VTZ_OK, "read as f64");
  int same = 1;
  for (int i = 0; i < W * H; i++) same &= wide[i] == (double)dec[i];
  CHECK(same, "f64 buffer equals the i16 decode");

  /* Bad requests: codes and messages, nothing written past the buffer. */
  rc = vtz_read(f, 0, 0, W, H, VTZ_U8, (uint8_t *)dec, W * H, 0);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT && strstr(vtz_last_error(), "u8"), "values that do not fit u8: rc %d", rc);
  rc = vtz_read(f, 0, 0, W, H, VTZ_I16, dec, sizeof dec - 2, 0);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT, "short buffer: rc %d", rc);
  rc = vtz_read(f, W - 10, 0, 20, 5, VTZ_I16, win, 20 * 5 * 2, 0);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT, "window outside the raster: rc %d", rc);
  rc = vtz_read(f, 0, 0, 1, 1, 9, win, 2, 0);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT, "unknown sample type: rc %d", rc);
  rc = vtz_read(f, 0, 0, 1, 1, VTZ_I16, NULL, 2, 0);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT, "null buffer: rc %d", rc);
  rc = vtz_read(f, 0, 0, 1, 1, VTZ_I16, win, 2, 0);
  CHECK(rc == VTZ_OK && strlen(vtz_last_error()) == 0, "a success clears the message");
  vtz_close(f);

  /* Limits: a raster over max_samples is refused before anything is decoded. */
  VtzLimits lim = {1000, 0};
  rc = vtz_open_memory(bytes, len, &lim, &f);
  CHECK(rc == VTZ_ERR_LIMIT && f == NULL, "limits: rc %d", rc);

  /* Every proper prefix is an error, never a success or a crash. */
  int prefix_ok = 1;
  for (size_t n = 0; n < len; n += (n < 64 ? 1 : 97)) {
    VtzFile *p = NULL;
    int r = vtz_open_memory(bytes, n, NULL, &p);
    if (r == VTZ_OK) {
      r = vtz_read(p, 0, 0, W, H, VTZ_I16, dec, sizeof dec, 1);
      vtz_close(p);
    }
    if (r == VTZ_OK || r == VTZ_ERR_PANIC) {
      prefix_ok = 0;
      fprintf(stderr, "prefix of %zu bytes: rc %d\n", n, r);
      break;
    }
  }
  CHECK(prefix_ok, "every proper prefix is rejected");
  /* Flipped bytes: an error or a decode, never a panic. */
  int flips_ok = 1;
  uint8_t *copy = malloc(len);
  for (size_t k = 0; k < 300 && copy; k++) {
    memcpy(copy, bytes, len);
    size_t at = (k * 7919) % len;
    copy[at] ^= (uint8_t)(1u << (k % 8));
    VtzFile *p = NULL;
    int r = vtz_open_memory(copy, len, NULL, &p);
    if (r == VTZ_OK) {
      r = vtz_read(p, 0, 0, W, H, VTZ_I16, dec, sizeof dec, 1);
      vtz_close(p);
    }
    if (r == VTZ_ERR_PANIC) {
      flips_ok = 0;
      fprintf(stderr, "flip at %zu: a panic: %s\n", at, vtz_last_error());
    }
  }
  free(copy);
  CHECK(flips_ok, "flipped bytes never panic");
  vtz_free_bytes(bytes, len);
}

static void test_lossless_float_and_tiles(const char *tmp) {
  static float src[W * H], dec[W * H], win[90 * 70];
  for (int i = 0; i < W * H; i++) src[i] = (float)(100.0 + 0.37 * (i % W) - 0.11 * (i / W) + 0.001 * (i % 7));
  src[5] = NAN;
  src[W * H - 1] = NAN;
  char path[4096];
  snprintf(path, sizeof path, "%s/capi_tiled.vtz", tmp);
  VtzEncodeOptions o = vtz_encode_options_init(); /* lossless */
  o.tile = 64;
  o.method = "residual";
  o.effort = 1;
  int rc = vtz_encode_to_path(src, VTZ_F32, W, H, &o, path);
  CHECK(rc == VTZ_OK, "encode_to_path: rc %d", rc);
  VtzFile *f = NULL;
  rc = vtz_open_path(path, NULL, &f);
  CHECK(rc == VTZ_OK && f, "open_path: rc %d", rc);
  if (!f) return;
  VtzInfo info;
  vtz_get_info(f, &info);
  CHECK(info.tiled == 1 && info.tile_width <= 64 && info.tile_height <= 64 && info.tile_cols == 5 &&
            info.tile_rows == 4,
        "tile grid %ux%u of %ux%u", info.tile_cols, info.tile_rows, info.tile_width, info.tile_height);
  CHECK(info.max_error == 0, "lossless: stored max error %g", info.max_error);
  CHECK(vtz_get_georef_geotiff(f, NULL, 0) == 0 && vtz_get_crs(f, NULL, 0) == 1,
        "no georeferencing: no GeoTIFF, an empty CRS");
  CHECK(vtz_read(f, 0, 0, W, H, VTZ_F32, dec, sizeof dec, 2) == VTZ_OK, "read tiled");
  CHECK(memcmp(src, dec, sizeof src) == 0, "lossless f32 round trip, NaNs kept, bit for bit");
  CHECK(vtz_read(f, 50, 60, 90, 70, VTZ_F32, win, sizeof win, 1) == VTZ_OK, "window across tiles");
  int same = 1;
  for (int y = 0; y < 70; y++) same &= memcmp(&win[y * 90], &dec[(60 + y) * W + 50], 90 * 4) == 0;
  CHECK(same, "a window across tile edges is the crop");
  /* Overview 2 of the lossless tiled file: every sample is a source sample (of its tile's
     own lattice, within 3 samples of the 4-th one), NaNs where the source has them. */
  {
    uint32_t ow = (W + 3) / 4, oh = (H + 3) / 4;
    rc = vtz_read_overview(f, 2, 0, 0, ow, oh, VTZ_F32, win, (size_t)ow * oh * 4, 0);
    int found = rc == VTZ_OK;
    for (uint32_t y = 0; found && y < oh; y++)
      for (uint32_t x = 0; found && x < ow; x++) {
        float v = win[y * ow + x];
        int hit = 0;
        for (int dy = -3; dy <= 3 && !hit; dy++)
          for (int dx = -3; dx <= 3 && !hit; dx++) {
            int sy = (int)(y * 4) + dy, sx = (int)(x * 4) + dx;
            if (sy < 0 || sx < 0 || sy >= H || sx >= W) continue;
            float u = src[sy * W + sx];
            hit = (isnan(u) && isnan(v)) || u == v;
          }
        found &= hit;
      }
    CHECK(found, "overview 2 of a lossless tiled file holds source samples near each position: rc %d", rc);
  }
  vtz_close(f);

  /* Bad options and paths. */
  o.effort = 10;
  CHECK(vtz_encode_to_path(src, VTZ_F32, W, H, &o, path) == VTZ_ERR_INVALID_ARGUMENT, "effort 10");
  o = vtz_encode_options_init();
  o.method = "no-such-method";
  CHECK(vtz_encode_to_path(src, VTZ_F32, W, H, &o, path) == VTZ_ERR_INVALID_ARGUMENT, "unknown method");
  o = vtz_encode_options_init();
  o.has_geotransform = 1;
  o.geotransform[2] = 0.5;
  CHECK(vtz_encode_to_path(src, VTZ_F32, W, H, &o, path) == VTZ_ERR_UNSUPPORTED, "rotated geotransform");
  f = (VtzFile *)1;
  rc = vtz_open_path("/nonexistent/x.vtz", NULL, &f);
  CHECK(rc == VTZ_ERR_IO && f == NULL && strstr(vtz_last_error(), "/nonexistent/x.vtz"),
        "missing file: rc %d, message names it", rc);
  CHECK(vtz_open_path(NULL, NULL, &f) == VTZ_ERR_INVALID_ARGUMENT, "null path");
  CHECK(vtz_open_memory((const uint8_t *)"not a vtz file at all", 21, NULL, &f) == VTZ_ERR_CORRUPT,
        "garbage");
  CHECK(vtz_get_info(NULL, &info) == VTZ_ERR_INVALID_ARGUMENT, "null file");
  vtz_close(NULL);
}

/* Two threads decoding one handle take turns and get the same bits. */
struct job {
  VtzFile *f;
  uint32_t w, h;
  float *out;
  int rc;
};
static void *run(void *p) {
  struct job *j = p;
  j->rc = vtz_read(j->f, 0, 0, j->w, j->h, VTZ_F32, j->out, (size_t)j->w * j->h * 4, 1);
  return NULL;
}

/* Each golden file decodes to the Rust decoder's samples (NAME.expected.f32). */
static void test_golden(const char *dir) {
  const char *names[] = {"v1_kauai_coast_flat", "v1_kauai_coast_flat_blocks", "v1_kauai_crop_fis",
                         "v1_kauai_crop_gdalmeta", "v1_kauai_crop_grid", "v1_kauai_crop_haar",
                         "v1_kauai_crop_residual", "v1_kauai_crop_residual_exceptions",
                         "v1_kauai_crop_residual_fast", "v1_kauai_crop_residual_fast_tight",
                         "v1_kauai_crop_residual_lossy", "v1_kauai_crop_residual_tight",
                         "v1_kauai_crop_sites", "v2_kauai_tiles"};
  for (size_t k = 0; k < sizeof names / sizeof *names; k++) {
    char p[4096], e[4096];
    snprintf(p, sizeof p, "%s/%s.vtz", dir, names[k]);
    snprintf(e, sizeof e, "%s/%s.expected.f32", dir, names[k]);
    size_t elen = 0;
    unsigned char *expected = read_file(e, &elen);
    CHECK(expected != NULL, "%s is missing", e);
    VtzFile *f = NULL;
    int rc = vtz_open_path(p, NULL, &f);
    CHECK(rc == VTZ_OK, "%s: open rc %d", names[k], rc);
    if (!f || !expected) {
      free(expected);
      continue;
    }
    VtzInfo info;
    vtz_get_info(f, &info);
    size_t n = (size_t)info.width * info.height;
    CHECK(n * 4 == elen, "%s: %zu samples, expected file %zu bytes", names[k], n, elen);
    float *a = malloc(n * 4), *b = malloc(n * 4);
    struct job j1 = {f, info.width, info.height, a, -1}, j2 = {f, info.width, info.height, b, -1};
    pthread_t t1, t2;
    pthread_create(&t1, NULL, run, &j1);
    pthread_create(&t2, NULL, run, &j2);
    pthread_join(t1, NULL);
    pthread_join(t2, NULL);
    CHECK(j1.rc == VTZ_OK && j2.rc == VTZ_OK, "%s: decode rc %d %d", names[k], j1.rc, j2.rc);
    CHECK(n * 4 == elen && memcmp(a, expected, elen) == 0, "%s: samples equal the Rust decoder's", names[k]);
    CHECK(memcmp(a, b, n * 4) == 0, "%s: two threads on one handle, same bits", names[k]);
    free(a);
    free(b);
    free(expected);
    vtz_close(f);
  }
  /* A point set is not a raster. */
  char p[4096];
  snprintf(p, sizeof p, "%s/v3_points.vtz", dir);
  VtzFile *f = NULL;
  int rc = vtz_open_path(p, NULL, &f);
  CHECK(rc == VTZ_ERR_UNSUPPORTED && f == NULL, "a point set: rc %d", rc);
  if (f) vtz_close(f);
}

/* Integer codes with a value mapping (README, "Output types"): a u16 raster mapped by
 * -32768 reads as the int16 values it holds (tiled and untiled, windows and overviews); a
 * scale of 0.1 reads as the codes with the band's offset and scale; a bound is in values. */
static void test_mapped_codes(void) {
  enum { MW = 200, MH = 150 };
  static uint16_t codes[MW * MH];
  for (int y = 0; y < MH; y++)
    for (int x = 0; x < MW; x++) /* values -37 .. ~1490 m around code 32768 */
      codes[y * MW + x] = (uint16_t)(32768 - 37 + lround(760.0 + 760.0 * sin(x * 0.05) * cos(y * 0.04)));
  for (int tiled = 0; tiled < 2; tiled++) {
    VtzEncodeOptions o = vtz_encode_options_init();
    o.has_offset_scale = 1;
    o.value_offset = -32768.0;
    o.value_scale = 1.0;
    o.max_error = 1.0;
    o.tile = tiled ? 64 : -1;
    uint8_t *bytes = NULL;
    size_t len = 0;
    int rc = vtz_encode(codes, VTZ_U16, MW, MH, &o, &bytes, &len);
    CHECK(rc == VTZ_OK, "mapped u16 encode (tiled %d): rc %d", tiled, rc);
    VtzFile *f = NULL;
    rc = vtz_open_memory(bytes, len, NULL, &f);
    CHECK(rc == VTZ_OK && f, "mapped open: rc %d", rc);
    if (!f) {
      vtz_free_bytes(bytes, len);
      continue;
    }
    VtzInfo info;
    vtz_get_info(f, &info);
    CHECK(info.sample_type == VTZ_U16 && info.value_type == VTZ_I16 && info.has_offset_scale == 0,
          "u16 codes mapped by -32768 read as i16 values: sample type %d, value type %d, offset/scale %d",
          info.sample_type, info.value_type, info.has_offset_scale);
    CHECK(info.has_range && info.min < 0, "the range is in values: %g", info.min);
    static int16_t v[MW * MH], win[40 * 30];
    rc = vtz_read_band(f, 0, 0, 0, MW, MH, VTZ_I16, v, sizeof v, 0);
    CHECK(rc == VTZ_OK, "read_band i16 (tiled %d): rc %d", tiled, rc);
    int worst = 0;
    for (int i = 0; i < MW * MH; i++) {
      int e = abs((int)v[i] - ((int)codes[i] - 32768));
      if (e > worst) worst = e;
    }
    CHECK(rc == VTZ_OK && worst <= 1, "values within the bound 1: %d", worst);
    rc = vtz_read_band(f, 0, 37, 41, 40, 30, VTZ_I16, win, sizeof win, 0);
    int same = rc == VTZ_OK;
    for (int y = 0; y < 30 && same; y++)
      same = memcmp(win + y * 40, v + (41 + y) * MW + 37, 40 * sizeof(int16_t)) == 0;
    CHECK(same, "a window of the i16 band is its crop (tiled %d): rc %d", tiled, rc);
    static int16_t ov[((MW + 1) / 2) * ((MH + 1) / 2)];
    rc = vtz_read_band(f, 1, 0, 0, (MW + 1) / 2, (MH + 1) / 2, VTZ_I16, ov, sizeof ov, 0);
    CHECK(rc == VTZ_OK, "overview 1 of the i16 band (tiled %d): rc %d", tiled, rc);
    static uint16_t u[MW * MH];
    rc = vtz_read(f, 0, 0, MW, MH, VTZ_U16, u, sizeof u, 0);
    CHECK(rc == VTZ_ERR_INVALID_ARGUMENT, "vtz_read gives values: negative ones do not fit u16: rc %d", rc);
    vtz_close(f);
    vtz_free_bytes(bytes, len);
  }
  /* Decimetres: the codes with offset -3276.8 and scale 0.1; the bound of 0.5 is in metres. */
  VtzEncodeOptions o = vtz_encode_options_init();
  o.has_offset_scale = 1;
  o.value_offset = -3276.8;
  o.value_scale = 0.1;
  o.max_error = 0.5;
  uint8_t *bytes = NULL;
  size_t len = 0;
  int rc = vtz_encode(codes, VTZ_U16, MW, MH, &o, &bytes, &len);
  CHECK(rc == VTZ_OK, "decimetre encode: rc %d", rc);
  VtzFile *f = NULL;
  if (rc == VTZ_OK) rc = vtz_open_memory(bytes, len, NULL, &f);
  if (f) {
    VtzInfo info;
    vtz_get_info(f, &info);
    CHECK(info.value_type == VTZ_U16 && info.has_offset_scale == 1 && info.value_offset == -3276.8 &&
              info.value_scale == 0.1 && info.max_error > 0.1 && info.max_error <= 0.5,
          "decimetre codes: value type %d, offset/scale %d %g %g, max error %g", info.value_type,
          info.has_offset_scale, info.value_offset, info.value_scale, info.max_error);
    static uint16_t c[MW * MH];
    rc = vtz_read_band(f, 0, 0, 0, MW, MH, VTZ_U16, c, sizeof c, 0);
    double worst = 0;
    for (int i = 0; i < MW * MH; i++) {
      double e = fabs(0.1 * ((double)c[i] - codes[i]));
      if (e > worst) worst = e;
    }
    CHECK(rc == VTZ_OK && worst <= 0.5 + 1e-9, "codes within 0.5 m: rc %d, %g m", rc, worst);
    vtz_close(f);
  }
  vtz_free_bytes(bytes, len);
  o.value_scale = 0.0;
  rc = vtz_encode(codes, VTZ_U16, MW, MH, &o, &bytes, &len);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT, "a zero scale: rc %d", rc);
  o.value_scale = 0.1;
  float fl[4] = {1, 2, 3, 4};
  rc = vtz_encode(fl, VTZ_F32, 2, 2, &o, &bytes, &len);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT, "an offset and scale over floats: rc %d", rc);
}

/* A VtzReader over bytes in memory: counts calls and bytes, checks the ranges it is given
   (ascending, non-empty, inside the file) and that no two calls overlap; fails on demand. */
struct mem_reader {
  const unsigned char *data;
  size_t len;
  int calls, ranges, closed, bad_ranges, overlap, in_flight;
  unsigned long long bytes;
  int fail_from_call; /* 0: never; k: the k-th call and later fail */
};
static int32_t mem_read_ranges(void *user, size_t n, const uint64_t *offsets, const size_t *lengths,
                               uint8_t *const *buffers, char *message, size_t message_cap) {
  struct mem_reader *m = user;
  if (__atomic_fetch_add(&m->in_flight, 1, __ATOMIC_SEQ_CST) != 0) m->overlap = 1;
  m->calls++;
  int rc = 0;
  if (m->fail_from_call && m->calls >= m->fail_from_call) {
    snprintf(message, message_cap, "HTTP 503 from the test reader (call %d)", m->calls);
    rc = 1;
  } else {
    for (size_t i = 0; i < n; i++) {
      if (lengths[i] == 0 || offsets[i] + lengths[i] > m->len ||
          (i > 0 && offsets[i] < offsets[i - 1] + lengths[i - 1]))
        m->bad_ranges = 1;
      if (offsets[i] + lengths[i] > m->len) { rc = 2; break; }
      memcpy(buffers[i], m->data + offsets[i], lengths[i]);
      m->bytes += lengths[i];
      m->ranges++;
    }
  }
  __atomic_fetch_sub(&m->in_flight, 1, __ATOMIC_SEQ_CST);
  return rc;
}
static void mem_close(void *user) { ((struct mem_reader *)user)->closed++; }

struct reader_job {
  VtzFile *f;
  int rc;
  int16_t *buf;
};
static void *read_on_a_thread(void *p) {
  struct reader_job *j = p;
  j->rc = vtz_read(j->f, 0, 0, 1024, 1024, VTZ_I16, j->buf, 1024 * 1024 * 2, 4);
  return NULL;
}

/* vtz_open_reader: a file read through callbacks decodes as vtz_open_memory's, bit for bit;
   a window reads only part of the file; failures give VTZ_ERR_IO with the callback's reason. */
static void test_reader(void) {
  enum { RW = 1024, RH = 1024 };
  static int16_t z[RW * RH], a[RW * RH], b[RW * RH], c[RW * RH], wa[100 * 70], wb[100 * 70];
  unsigned s = 12345;
  for (int i = 0; i < RW * RH; i++) {
    s = s * 1103515245u + 12345u;
    z[i] = (int16_t)(500 + (i % RW) / 3 + (i / RW) / 5 + (int)((s >> 16) % 64));
  }
  VtzEncodeOptions o = vtz_encode_options_init(); /* lossless */
  o.tile = 256;
  o.method = "residual";
  o.effort = 1;
  uint8_t *bytes = NULL;
  size_t len = 0;
  int rc = vtz_encode(z, VTZ_I16, RW, RH, &o, &bytes, &len);
  CHECK(rc == VTZ_OK && len > 4 * 65536, "reader test file: rc %d, %zu bytes", rc, len);
  if (rc != VTZ_OK) return;
  VtzFile *fm = NULL, *fr = NULL;
  CHECK(vtz_open_memory(bytes, len, NULL, &fm) == VTZ_OK, "open_memory");

  struct mem_reader m = {bytes, len, 0, 0, 0, 0, 0, 0, 0, 0};
  VtzReader r = {&m, len, mem_read_ranges, mem_close, "mem://test.vtz"};
  rc = vtz_open_reader(&r, NULL, &fr);
  CHECK(rc == VTZ_OK && fr && m.closed == 0, "open_reader: rc %d", rc);
  if (!fm || !fr) return;
  VtzInfo im, ir;
  vtz_get_info(fm, &im);
  vtz_get_info(fr, &ir);
  CHECK(im.width == ir.width && im.height == ir.height && im.sample_type == ir.sample_type &&
            im.max_error == ir.max_error && im.tile_width == ir.tile_width && im.tile_cols == ir.tile_cols &&
            ir.tiled == 1 && ir.tile_cols == 4 && ir.file_bytes == len,
        "the same info through the reader as from memory");
  CHECK(m.bytes < len / 2, "opening read %llu of %zu bytes", m.bytes, len);
  /* A window inside tile (1, 1): the head, the index, that tile's block (and margins). */
  rc = vtz_read(fr, 300, 310, 100, 70, VTZ_I16, wb, sizeof wb, 2);
  CHECK(rc == VTZ_OK, "window through the reader: rc %d", rc);
  CHECK(vtz_read(fm, 300, 310, 100, 70, VTZ_I16, wa, sizeof wa, 2) == VTZ_OK, "window from memory");
  CHECK(memcmp(wa, wb, sizeof wa) == 0, "the window through callbacks equals vtz_open_memory's bit for bit");
  CHECK(m.bytes < len / 2, "the window read %llu of %zu bytes in %d calls", m.bytes, len, m.calls);
  /* The whole raster, from two threads at once on the same handle. */
  CHECK(vtz_read(fm, 0, 0, RW, RH, VTZ_I16, a, sizeof a, 0) == VTZ_OK, "full read from memory");
  CHECK(memcmp(a, z, sizeof a) == 0, "lossless");
  struct reader_job j1 = {fr, -1, b}, j2 = {fr, -1, c};
  pthread_t t1, t2;
  pthread_create(&t1, NULL, read_on_a_thread, &j1);
  pthread_create(&t2, NULL, read_on_a_thread, &j2);
  pthread_join(t1, NULL);
  pthread_join(t2, NULL);
  CHECK(j1.rc == VTZ_OK && j2.rc == VTZ_OK && memcmp(a, b, sizeof a) == 0 && memcmp(a, c, sizeof a) == 0,
        "full reads through callbacks on two threads equal vtz_open_memory's: rc %d %d", j1.rc, j2.rc);
  CHECK(!m.overlap, "read_ranges is never called by two threads at once for one handle");
  CHECK(!m.bad_ranges, "ranges are ascending, non-empty and inside the file");
  /* A failing callback after the open: VTZ_ERR_IO with its reason; the handle still works. */
  m.fail_from_call = m.calls + 1;
  rc = vtz_read(fr, 700, 700, 100, 70, VTZ_I16, wb, sizeof wb, 1);
  CHECK(rc == VTZ_ERR_IO && strstr(vtz_last_error(), "HTTP 503 from the test reader") &&
            strstr(vtz_last_error(), "mem://test.vtz"),
        "a failing read callback: rc %d", rc);
  m.fail_from_call = 0;
  rc = vtz_read(fr, 700, 700, 100, 70, VTZ_I16, wb, sizeof wb, 1);
  CHECK(rc == VTZ_OK, "a later read succeeds: rc %d", rc);
  vtz_close(fr);
  CHECK(m.closed == 1, "vtz_close calls close once (%d)", m.closed);
  vtz_close(fm);

  /* Failing opens: *out is null, close is called once, the status names the cause. */
  struct mem_reader m2 = {bytes, len, 0, 0, 0, 0, 0, 0, 0, 1};
  VtzReader r2 = {&m2, len, mem_read_ranges, mem_close, NULL};
  fr = (VtzFile *)1;
  rc = vtz_open_reader(&r2, NULL, &fr);
  CHECK(rc == VTZ_ERR_IO && fr == NULL && m2.closed == 1 && strstr(vtz_last_error(), "HTTP 503"),
        "a callback failing on the open: rc %d, closed %d", rc, m2.closed);
  struct mem_reader m3 = {bytes, len, 0, 0, 0, 0, 0, 0, 0, 0};
  VtzReader r3 = {&m3, len - 1000, mem_read_ranges, mem_close, "short"};
  rc = vtz_open_reader(&r3, NULL, &fr);
  CHECK(rc == VTZ_ERR_CORRUPT && fr == NULL && m3.closed == 1, "a length shorter than the file: rc %d", rc);
  VtzReader r4 = {&m3, len, NULL, mem_close, "no callback"};
  rc = vtz_open_reader(&r4, NULL, &fr);
  CHECK(rc == VTZ_ERR_INVALID_ARGUMENT && fr == NULL && m3.closed == 2, "no read_ranges: rc %d", rc);
  CHECK(vtz_open_reader(NULL, NULL, &fr) == VTZ_ERR_INVALID_ARGUMENT && fr == NULL, "a null reader");
  VtzLimits lim = {0, 100}; /* sections of at most 100 bytes: the tile index is larger */
  rc = vtz_open_reader(&r, &lim, &fr);
  CHECK(rc == VTZ_ERR_LIMIT && fr == NULL && m.closed == 2, "limits apply: rc %d, closed %d", rc, m.closed);
  vtz_free_bytes(bytes, len);
}

int main(int argc, char **argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: capi_test GOLDEN_DIR TMP_DIR\n");
    return 2;
  }
  CHECK(strlen(vtz_version()) > 0, "version");
  test_round_trip_and_windows();
  test_lossless_float_and_tiles(argv[2]);
  test_golden(argv[1]);
  test_mapped_codes();
  test_reader();
  printf("capi_test (vtz %s): %d checks, %d failed\n", vtz_version(), checks, failures);
  return failures ? 1 : 0;
}
