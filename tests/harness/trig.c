/*
 * The generated sin and cos (static inline in gyrostat.c, included here)
 * against glibc's: for each range [lo, hi] given, N log-uniform arguments of
 * both signs, then the doubles nearest k pi/2 (k <= 2^20) and their
 * neighbours. Prints per range the largest error in ulps of glibc's result
 * and the largest absolute error in ulps of x (the backward error: the
 * result is sin or cos of a point that close to x). Last, how many arguments
 * the scalar functions and their branch-free _lanes twins answered with
 * different bits (there should be none).
 *
 * Usage: trig N lo hi [lo hi ...]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gyrostat.c"

static double ulps(double got, double want)
{
    const double a = fabs(want);
    return got == want ? 0.0 : fabs(got - want) / (nextafter(a, INFINITY) - a);
}

static long differ; /* arguments where a function and its _lanes twin differ */

static int same_bits(double a, double b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

static void check(double x, double *worst, double *backward)
{
    differ += !same_bits(gyrostat_sin(x), gyrostat_sin_lanes(x))
              || !same_bits(gyrostat_cos(x), gyrostat_cos_lanes(x));
    const double es = ulps(gyrostat_sin(x), sin(x)), ec = ulps(gyrostat_cos(x), cos(x));
    const double abs_err = fmax(fabs(gyrostat_sin(x) - sin(x)), fabs(gyrostat_cos(x) - cos(x)));
    const double ux = nextafter(fabs(x), INFINITY) - fabs(x);
    *worst = fmax(*worst, fmax(es, ec));
    *backward = fmax(*backward, abs_err / ux);
}

int main(int argc, char **argv)
{
    unsigned long s = 88172645463325252ul;
    long n, i, k;
    int r, j;
    double worst = 0.0, backward = 0.0;
    if (argc < 4 || argc % 2) {
        return 2;
    }
    n = atol(argv[1]);
    for (r = 2; r + 1 < argc; r += 2) {
        const double lo = atof(argv[r]), hi = atof(argv[r + 1]);
        worst = backward = 0.0;
        for (i = 0; i < n; ++i) {
            double u, x;
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            u = (double)(s >> 11) / 9007199254740992.0;
            x = lo * pow(hi / lo, u);
            check(s & 1 ? -x : x, &worst, &backward);
        }
        printf("%g %g %.3f %.3f\n", lo, hi, worst, backward);
    }
    worst = backward = 0.0;
    for (k = 1; k <= 1048576; ++k) {
        double x = (double)k * 1.5707963267948966;
        for (j = 0; j < 3; ++j) {
            x = nextafter(x, 0.0);
        }
        for (j = 0; j < 7; ++j) {
            check(x, &worst, &backward);
            x = nextafter(x, INFINITY);
        }
    }
    printf("near_k_pi/2 - %.3f %.3f\n", worst, backward);
    printf("special %g %g %g %g %g %g\n", gyrostat_sin(-0.0), gyrostat_cos(0.0),
           gyrostat_sin(INFINITY), gyrostat_cos(NAN), gyrostat_sin(1125899906842624.0),
           gyrostat_sin(1125899906842624.0 * 2.0));
    printf("lanes_twins_differ %ld\n", differ);
    return 0;
}
