/*
 * The lane-batched integrators without Python: integrates a batch of
 * perturbed default-scene states with dop853_batch, dopri5_batch,
 * rk4_batch, rodas4_batch and radau5_batch, and each state again with the single-trajectory
 * function;
 * writes every final state, statistics record and code (binary, batch
 * first, then single). tests/test_lanes.py builds it with several
 * GYROSTAT_LANES values, with and without OpenMP, and compares the bytes.
 *
 * Usage: lanes N OUT. Trajectory 3 starts with a NaN (code 3), trajectory 5
 * is given q2 = 1.57 and u1 = 2 (gimbal lock: code 6 under rk4); the
 * second dop853, rodas4 and radau5 batches have a budget of 20 steps (code 2 for
 * some).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gyrostat.h"
#include "gyrostat_ode.h"

#define NX GYROSTAT_NX

static void start(double *xs, int n)
{
    const double x0[NX] = {0, 0.1, 0, 0, 0, 0, 0, 0.2, 1.0, -0.1, 50.0, 1.0, 0, 0};
    unsigned long s = 12345;
    int i, j;
    for (i = 0; i < n; ++i) {
        memcpy(xs + i * NX, x0, sizeof x0);
        for (j = 7; j < 10; ++j) {
            s = s * 6364136223846793005ul + 1442695040888963407ul;
            xs[i * NX + j] *= 0.9 + 0.2 * (double)(s >> 11) / 9007199254740992.0;
        }
    }
    xs[3 * NX + 0] = NAN;
    xs[5 * NX + 1] = 1.57;
    xs[5 * NX + 7] = 2.0;
}

static void put(FILE *f, const double *xs, const gyrostat_stats *st, const int *codes, int n)
{
    fwrite(xs, sizeof *xs, (size_t)n * NX, f);
    fwrite(st, sizeof *st, (size_t)n, f);
    fwrite(codes, sizeof *codes, (size_t)n, f);
}

int main(int argc, char **argv)
{
    const double p[GYROSTAT_NP] = {100, 5, 12, 9, 15, 0.8, 0.02, 0.03, 0.2, -0.1, 9.81, 0.01};
    double c[GYROSTAT_NC], *xs;
    gyrostat_stats *st;
    int *codes, n, i, run;
    FILE *out;
    if (argc != 3 || gyrostat_setup(p, c) != GYROSTAT_OK) {
        return 2;
    }
    n = atoi(argv[1]);
    xs = malloc(sizeof *xs * (size_t)n * NX);
    st = malloc(sizeof *st * (size_t)n);
    codes = malloc(sizeof *codes * (size_t)n);
    out = fopen(argv[2], "wb");
    if (!xs || !st || !codes || !out || n < 8) {
        return 2;
    }
    for (run = 0; run < 2; ++run) {  /* the batch, then one call per trajectory */
        const long budget[2] = {100000, 20};
        int b;
        for (b = 0; b < 2; ++b) {
            start(xs, n);
            if (run == 0) {
                gyrostat_dop853_batch((size_t)n, 0.0, 10.0, xs, c, 1e-9, 1e-9, 0.0, budget[b], st,
                                      codes);
            } else {
                for (i = 0; i < n; ++i) {
                    codes[i] = gyrostat_dop853(0.0, 10.0, xs + i * NX, c, 1e-9, 1e-9, 0.0,
                                               budget[b], st + i);
                }
            }
            put(out, xs, st, codes, n);
        }
        start(xs, n);
        if (run == 0) {
            gyrostat_dopri5_batch((size_t)n, 0.0, 3.0, xs, c, 1e-7, 1e-9, 1e-3, 100000, st, codes);
        } else {
            for (i = 0; i < n; ++i) {
                codes[i] = gyrostat_dopri5(0.0, 3.0, xs + i * NX, c, 1e-7, 1e-9, 1e-3, 100000,
                                           st + i);
            }
        }
        put(out, xs, st, codes, n);
        start(xs, n);
        if (run == 0) {
            gyrostat_rk4_batch((size_t)n, 0.0, 1.0, 200, xs, c, st, codes);
        } else {
            for (i = 0; i < n; ++i) {
                codes[i] = gyrostat_rk4(0.0, 1.0, 200, xs + i * NX, c, st + i);
            }
        }
        put(out, xs, st, codes, n);
        for (b = 0; b < 2; ++b) {
            start(xs, n);
            if (run == 0) {
                gyrostat_rodas4_batch((size_t)n, 0.0, 3.0, xs, c, 1e-7, 1e-9, 0.0, budget[b], st,
                                      codes);
            } else {
                for (i = 0; i < n; ++i) {
                    codes[i] = gyrostat_rodas4(0.0, 3.0, xs + i * NX, c, 1e-7, 1e-9, 0.0,
                                               budget[b], st + i);
                }
            }
            put(out, xs, st, codes, n);
        }
        for (b = 0; b < 2; ++b) {
            start(xs, n);
            if (run == 0) {
                gyrostat_radau5_batch((size_t)n, 0.0, 3.0, xs, c, 1e-7, 1e-9, 0.0, budget[b], st,
                                      codes);
            } else {
                for (i = 0; i < n; ++i) {
                    codes[i] = gyrostat_radau5(0.0, 3.0, xs + i * NX, c, 1e-7, 1e-9, 0.0,
                                               budget[b], st + i);
                }
            }
            put(out, xs, st, codes, n);
        }
    }
    return fclose(out) != 0;
}
