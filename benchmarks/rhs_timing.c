/*
 * Nanoseconds per gyrostat_rhs call, best of REPEATS runs of CALLS calls,
 * for benchmarks/bench_cmake_default.py (make bench-lib). The state moves a
 * little on every call and every derivative is summed, so no call can be
 * left out. The clock is the process's CPU time, so that time the shared
 * machine gives to others is not counted. Prints "ns_per_call <best>
 * checksum <sum>".
 */
#define _POSIX_C_SOURCE 199309L
#include "gyrostat.h"

#include <stdio.h>
#include <time.h>

#define CALLS 2000000L
#define REPEATS 7

static double seconds(void)
{
    struct timespec now;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &now);
    return (double)now.tv_sec + 1e-9 * (double)now.tv_nsec;
}

int main(void)
{
    const double p[GYROSTAT_NP] = {100.0, 5.0, 12.0, 9.0, 15.0, 0.8, 0.02, 0.03, 0.2, -0.1, 9.81, 0.01};
    /* q2 = 0.1, u1..u5 = 0.2, 1.0, -0.1, 50.0, 1.0: the scene's own start */
    double x[GYROSTAT_NX] = {0.0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.2, 1.0, -0.1, 50.0, 1.0, 0.0, 0.0};
    double c[GYROSTAT_NC], dxdt[GYROSTAT_NX], sum = 0.0, best = 1e30;
    long call;
    int repeat, i;

    if (gyrostat_setup(p, c) != 0) return 1;
    for (repeat = 0; repeat < REPEATS; ++repeat) {
        double start = seconds(), elapsed;
        for (call = 0; call < CALLS; ++call) {
            x[1] += 1e-12;
            gyrostat_rhs(0.0, x, c, dxdt);
            for (i = 0; i < GYROSTAT_NX; ++i) sum += dxdt[i];
        }
        elapsed = (seconds() - start) * 1e9 / (double)CALLS;
        if (elapsed < best) best = elapsed;
    }
    printf("ns_per_call %.2f checksum %.6g\n", best, sum);
    return 0;
}
