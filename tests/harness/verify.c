/*
 * The verify path without Python, for the sanitizers: reads parameter sets
 * and states from a binary file, runs setup on each set, and for the accepted
 * ones the RHS at every state and DOP853 and Rodas4 from the first few; writes
 * the setup codes, derivatives and final states for the test to compare with
 * the numpy reference. Built by tests/test_strict.py with ASan and UBSan.
 *
 * Input:  int32 np, ns, then np x GYROSTAT_NP doubles, ns x GYROSTAT_NX doubles.
 * Output: per parameter set: int32 code, then (code 0 only) ns x NX derivatives
 *         and 2 x NINT x NX final states (dop853, then rodas4).
 */
#include <stdio.h>
#include <stdlib.h>

#include "gyrostat.h"
#include "gyrostat_ode.h"

#define NINT 3

static int read_all(FILE *f, void *buf, size_t size, size_t n)
{
    return fread(buf, size, n, f) == n;
}

int main(int argc, char **argv)
{
    FILE *in, *out;
    int np, ns, i, j;
    double *p, *x, c[GYROSTAT_NC], dxdt[GYROSTAT_NX], y[GYROSTAT_NX];
    gyrostat_stats stats;

    if (argc != 3 || !(in = fopen(argv[1], "rb")) || !(out = fopen(argv[2], "wb"))) {
        fprintf(stderr, "usage: verify IN OUT\n");
        return 2;
    }
    if (!read_all(in, &np, sizeof np, 1) || !read_all(in, &ns, sizeof ns, 1) || ns < NINT) {
        return 2;
    }
    p = malloc(sizeof *p * (size_t)np * GYROSTAT_NP);
    x = malloc(sizeof *x * (size_t)ns * GYROSTAT_NX);
    if (!p || !x || !read_all(in, p, sizeof *p, (size_t)np * GYROSTAT_NP)
        || !read_all(in, x, sizeof *x, (size_t)ns * GYROSTAT_NX)) {
        return 2;
    }
    for (i = 0; i < np; ++i) {
        const int code = gyrostat_setup(p + (size_t)i * GYROSTAT_NP, c);
        fwrite(&code, sizeof code, 1, out);
        if (code != GYROSTAT_OK) {
            continue;
        }
        for (j = 0; j < ns; ++j) {
            gyrostat_rhs(0.0, x + (size_t)j * GYROSTAT_NX, c, dxdt);
            fwrite(dxdt, sizeof *dxdt, GYROSTAT_NX, out);
        }
        for (j = 0; j < 2 * NINT; ++j) {
            int k;
            for (k = 0; k < GYROSTAT_NX; ++k) {
                y[k] = x[(size_t)(j % NINT) * GYROSTAT_NX + (size_t)k];
            }
            if (j < NINT) {
                gyrostat_dop853(0.0, 0.5, y, c, 1e-10, 1e-10, 0.0, 1000000, &stats);
            } else {
                gyrostat_rodas4(0.0, 0.5, y, c, 1e-10, 1e-10, 0.0, 1000000, &stats);
            }
            fwrite(y, sizeof *y, GYROSTAT_NX, out);
        }
    }
    free(p);
    free(x);
    fclose(in);
    return fclose(out) != 0;
}
