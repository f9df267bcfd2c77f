/*
 * A C program that calls the C library and, through gyrostat_f.h, the
 * Fortran one, with the headers included together: the same setup, rhs,
 * Jacobian and dop853 run from both, and what each refuses. Prints
 * "name value" lines for tests/test_cmake_package.py.
 */
#include "gyrostat.h"
#include "gyrostat_f.h"
#include "gyrostat_ode.h"

#include <math.h>
#include <stdio.h>

static double worst(const double *a, const double *b, int n)
{
    double w = 0.0;
    int i;
    for (i = 0; i < n; ++i) {
        w = fmax(w, fabs(a[i] - b[i]) / (1.0 + fabs(b[i])));
    }
    return w;
}

int main(void)
{
    double p[GYROSTAT_NP] = {100.0, 5.0, 12.0, 9.0, 15.0, 0.8, 0.02, 0.03, 0.2, -0.1, 9.81, 0.01};
    /* q2 = 0.1, u1..u5 = 0.2, 1.0, -0.1, 50.0, 1.0: the scene's own start */
    double x[GYROSTAT_NX] = {0.0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.2, 1.0, -0.1, 50.0, 1.0, 0.0, 0.0};
    double c[GYROSTAT_NC], cf[GYROSTAT_NC], xf[GYROSTAT_NX];
    double d[GYROSTAT_NX], df[GYROSTAT_NX];
    double J[GYROSTAT_NX * GYROSTAT_NX], Jf[GYROSTAT_NX * GYROSTAT_NX];
    gyrostat_stats s, sf;
    int code, codef, i;

    code = gyrostat_setup(p, c);
    codef = gyrostat_f_setup(p, cf);
    printf("setup_codes %d\n", code + 10 * codef);
    for (i = 0; i < GYROSTAT_NX; ++i) xf[i] = x[i];
    gyrostat_rhs(0.0, x, c, d);
    gyrostat_f_rhs(0.0, x, cf, df);
    printf("rhs_difference %.3g\n", worst(df, d, GYROSTAT_NX));
    gyrostat_jac(0.0, x, c, J);
    gyrostat_f_jac(0.0, x, cf, Jf);
    printf("jac_difference %.3g\n", worst(Jf, J, GYROSTAT_NX * GYROSTAT_NX));
    code = gyrostat_dop853(0.0, 1.0, x, c, 1e-10, 1e-10, 0.0, 100000, &s);
    codef = gyrostat_f_dop853(0.0, 1.0, xf, cf, 1e-10, 1e-10, 0.0, 100000, &sf);
    printf("dop853_codes %d\n", code + 10 * codef);
    printf("dop853_difference %.3g\n", worst(xf, x, GYROSTAT_NX));
    printf("dop853_steps %ld %ld\n", s.accepted, sf.accepted);
    p[0] = -1.0;
    code = gyrostat_f_setup(p, cf);
    printf("refused %d %s\n", code, gyrostat_strerror(code));
    code = gyrostat_f_dop853(0.0, 1.0, xf, cf, 0.0, 1e-10, 0.0, 100000, NULL);
    printf("refused %d %s\n", code, gyrostat_ode_strerror(code));
    return 0;
}
