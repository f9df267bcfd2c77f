/*
 * The Taylor step's step_log2 and step_exp2 (static inline in
 * gyrostat_ode.c, included here) against glibc's log2 and exp2: N
 * log-uniform positive arguments of log2 over [1e-300, 1e300], N uniform
 * arguments of exp2 over [-1074, 1023]. Prints the largest absolute error
 * of step_log2 (its result is divided by the order, then fed to exp2), the
 * largest relative error of step_exp2 where the result is normal, its
 * largest error where the result is subnormal (in units of the relative
 * bound times the result plus 2^-1074: at most 1 passes), the count of the
 * bit helpers' results that differ from frexp's and ldexp's (every
 * exponent of a normal double, random significands), the count of powers
 * of 2 whose step_log2 is not exact, and the special values: step_log2 of
 * +inf, 0, NaN; step_exp2 of +inf, -inf, NaN, 1024, -1076.
 *
 * Usage: elementary N
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "gyrostat_ode.c"

#define EXP2_REL 1.2e-7

int main(int argc, char **argv)
{
    const long n = argc > 1 ? atol(argv[1]) : 100000;
    double worst_log = 0.0, worst_exp = 0.0, worst_sub = 0.0;
    long i, bits_bad = 0, powers_bad = 0;
    srand(7);
    for (i = 0; i < n; ++i) {
        const double u = (double)rand() / RAND_MAX;
        const double z = pow(10.0, -300.0 + 600.0 * u);
        const double y = -1074.0 + 2097.0 * u;
        const double el = fabs(step_log2(z) - log2(z));
        const double want = exp2(y);
        const double got = step_exp2(y);
        worst_log = el > worst_log ? el : worst_log;
        if (want >= DBL_MIN) {
            const double ee = fabs(got / want - 1.0);
            worst_exp = ee > worst_exp ? ee : worst_exp;
        } else {
            const double es = fabs(got - want) / (EXP2_REL * want + ldexp(1.0, -1074));
            worst_sub = es > worst_sub ? es : worst_sub;
        }
    }
    for (i = -1022; i <= 1023; ++i) {
        const double x = ldexp(1.0 + (double)rand() / RAND_MAX * (1.0 - DBL_EPSILON), (int)i);
        int e;
        const double f = frexp(x, &e);
        bits_bad += bits_exponent(x) != (double)(e - 1) || bits_significand(x) != 2.0 * f;
        bits_bad += bits_pow2((double)i) != ldexp(1.0, (int)i);
        powers_bad += step_log2(ldexp(1.0, (int)i)) != (double)i;
    }
    printf("log2_abs %.3g\n", worst_log);
    printf("exp2_rel %.3g\n", worst_exp);
    printf("exp2_subnormal %.3g\n", worst_sub);
    printf("bits_bad %ld\n", bits_bad);
    printf("powers_bad %ld\n", powers_bad);
    printf("special %g %g %g %g %g %g %g %g\n", step_log2(INFINITY), step_log2(0.0),
           step_log2(NAN), step_exp2(INFINITY), step_exp2(-INFINITY), step_exp2(NAN),
           step_exp2(1024.0), step_exp2(-1076.0));
    return 0;
}
