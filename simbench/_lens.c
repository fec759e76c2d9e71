/*
 * The lens model's remap grids and its layered defocus blur (simbench/optics.py), in C: compiled into the same library as
 * simbench/_ckernels.c (pyproject.toml), with the same flags and the same contract (every loop
 * gives the bits of the numpy expression it replaces; tests/test_optics.py compares them).
 *
 * A file of its own because recordings and projector drives depend on it: simbench.simulate puts
 * this file's digest, and not the decoder's loops, in every recording's and drive's cache key.
 */
#include <stdint.h>

/* Row helpers stay out of line, as in _ckernels.c. */
#define ROW_FN static __attribute__((noinline))

/* Brown-Conrady lens model on the pixel grid of a camera (simbench.optics: distort_normalized,
 * undistort_normalized), in float64 and in numpy's operation order, so the maps are the bits
 * numpy gives; one row at a time so that every loop runs over contiguous pixels.
 * grid x = (j - cx) / f, y = (i - cy) / f; map = (float)(model(x, y) * f + c). */
ROW_FN void brown_forward_row(int64_t w, const double *restrict x, double y, const double *restrict d,
                             double *restrict xd, double *restrict yd) {
    const double k1 = d[0], k2 = d[1], p1 = d[2], p2 = d[3], k3 = d[4];
    for (int64_t j = 0; j < w; j++) {
        const double r2 = x[j] * x[j] + y * y;
        const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        xd[j] = x[j] * radial + 2.0 * p1 * x[j] * y + p2 * (r2 + 2.0 * x[j] * x[j]);
        yd[j] = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x[j] * y;
    }
}

ROW_FN void brown_inverse_step(int64_t w, const double *restrict xd, double yd, const double *restrict d,
                              double *restrict x, double *restrict y) {
    const double k1 = d[0], k2 = d[1], p1 = d[2], p2 = d[3], k3 = d[4];
    for (int64_t j = 0; j < w; j++) {
        const double r2 = x[j] * x[j] + y[j] * y[j];
        const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        const double dx = 2.0 * p1 * x[j] * y[j] + p2 * (r2 + 2.0 * x[j] * x[j]);
        const double dy = p1 * (r2 + 2.0 * y[j] * y[j]) + 2.0 * p2 * x[j] * y[j];
        x[j] = (xd[j] - dx) / radial;
        y[j] = (yd - dy) / radial;
    }
}

ROW_FN void to_pixels(int64_t w, const double *restrict u, double f, double c, float *restrict out) {
    for (int64_t j = 0; j < w; j++) out[j] = (float)(u[j] * f + c);
}

/* inverse = 0: where each ideal pixel is recorded, K D(K^-1 q); inverse = 1: where each
 * recorded pixel's light comes from, K D^-1(K^-1 p) by `iterations` fixed-point steps (OpenCV's
 * method).  scratch: 3 w doubles. */
void brown_maps(int64_t h, int64_t w, double f, double cx, double cy, const double *restrict d, int64_t inverse,
                int64_t iterations, double *restrict scratch, float *restrict map_x, float *restrict map_y) {
    double *gx = scratch, *a = scratch + w, *b = scratch + 2 * w;
    for (int64_t j = 0; j < w; j++) gx[j] = ((double)j - cx) / f;
    for (int64_t i = 0; i < h; i++) {
        const double gy = ((double)i - cy) / f;
        if (!inverse) {
            brown_forward_row(w, gx, gy, d, a, b);
        } else {
            for (int64_t j = 0; j < w; j++) {
                a[j] = gx[j];
                b[j] = gy;
            }
            for (int64_t k = 0; k < iterations; k++) brown_inverse_step(w, gx, gy, d, a, b);
        }
        to_pixels(w, a, f, cx, map_x + i * w);
        to_pixels(w, b, f, cy, map_y + i * w);
    }
}

/* One level of simbench.optics.depth_varying_blur, added to out over the box of rows r0..r1-1
 * and columns c0..c1-1: a pixel whose lower level lo is k weighs the level's image cur by
 * 1 - frac, one whose lo is k - 1 by frac, any other by 0; out += weight * cur, channel by
 * channel (numpy's float32 operations: the weight as the sum of the two where()s, the product,
 * then the sum).  lo, frac: (H, w_full); cur, out: (H, w_full, c). */
void blur_level_add(int64_t w_full, int64_t c, int64_t r0, int64_t r1, int64_t c0, int64_t c1, int64_t k,
                    const int64_t *restrict lo, const float *restrict frac, const float *restrict cur,
                    float *restrict out) {
    for (int64_t i = r0; i < r1; i++) {
        for (int64_t j = c0; j < c1; j++) {
            const int64_t at = i * w_full + j, l = lo[at];
            const float f = frac[at];
            const float w = (l == k ? 1.0f - f : 0.0f) + (l == k - 1 ? f : 0.0f);
            for (int64_t ch = 0; ch < c; ch++) out[at * c + ch] += w * cur[at * c + ch];
        }
    }
}
