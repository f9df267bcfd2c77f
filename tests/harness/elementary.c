/*
 * The Taylor step's step_log and step_exp (static inline in gyrostat_ode.c,
 * included here) against glibc's log and exp: N log-uniform positive
 * arguments of log over [1e-300, 1e300], N uniform arguments of exp over
 * [-740, 709]. Prints the largest error of step_log in ulps of
 * max(|log z|, 1) (its result feeds exp: near z = 1, what matters is the
 * absolute error), the largest
 * error of step_exp in ulps of glibc's result (normal results), its largest
 * error in units of 2^-1074 where the result is subnormal (y in [-745,
 * -708.4]: 2^k in two factors), the count of the bit helpers' results that
 * differ from frexp's and ldexp's (every exponent of a normal double, random
 * significands), and the special values: step_log of +inf, 0, NaN; step_exp
 * of +inf, -inf, NaN, 710, -746.
 *
 * Usage: elementary N
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "gyrostat_ode.c"

static double ulps(double got, double want)
{
    const double a = fabs(want);
    return got == want ? 0.0 : fabs(got - want) / (nextafter(a, INFINITY) - a);
}

int main(int argc, char **argv)
{
    const long n = argc > 1 ? atol(argv[1]) : 100000;
    double worst_log = 0.0, worst_exp = 0.0;
    long i;
    srand(7);
    for (i = 0; i < n; ++i) {
        const double u = (double)rand() / RAND_MAX;
        const double z = pow(10.0, -300.0 + 600.0 * u);
        const double y = -740.0 + 1449.0 * u;
        const double el = ulps(step_log(z), log(z)) * (fabs(log(z)) < 1.0 ? fabs(log(z)) : 1.0);
        const double ee = exp(y) >= DBL_MIN ? ulps(step_exp(y), exp(y)) : 0.0;
        worst_log = el > worst_log ? el : worst_log;
        worst_exp = ee > worst_exp ? ee : worst_exp;
    }
    double worst_sub = 0.0;
    long bits_bad = 0;
    for (i = 0; i < n; ++i) {
        const double u = (double)rand() / RAND_MAX;
        const double y = -745.0 + 36.6 * u;
        const double e = fabs(step_exp(y) - exp(y)) / ldexp(1.0, -1074);
        worst_sub = exp(y) < DBL_MIN && e > worst_sub ? e : worst_sub;
    }
    for (i = -1022; i <= 1023; ++i) {
        const double x = ldexp(1.0 + (double)rand() / RAND_MAX * (1.0 - DBL_EPSILON), (int)i);
        int e;
        const double f = frexp(x, &e);
        bits_bad += bits_exponent(x) != (double)(e - 1) || bits_significand(x) != 2.0 * f;
        bits_bad += bits_pow2((double)i) != ldexp(1.0, (int)i);
    }
    printf("log_ulps %.3g\n", worst_log);
    printf("exp_ulps %.3g\n", worst_exp);
    printf("exp_subnormal %.3g\n", worst_sub);
    printf("bits_bad %ld\n", bits_bad);
    printf("special %g %g %g %g %g %g %g %g\n", step_log(INFINITY), step_log(0.0), step_log(NAN),
           step_exp(INFINITY), step_exp(-INFINITY), step_exp(NAN), step_exp(710.0),
           step_exp(-746.0));
    return 0;
}
