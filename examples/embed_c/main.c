/*
 * Embedding the generated C in a plain C99 program: no Python, no gyrogen,
 * only the library built from generated/gyrostat/ (its CMake package:
 * examples/CMakeLists.txt links gyrostat::gyrostat).
 *
 * A dual-spin-like gyrostat (a 500 kg carrier with a 10 kg momentum wheel
 * spinning at 100 rad/s, driven by a 0.01 N m motor) is integrated for 10 s
 * with the generated fixed-step classical RK4 (dt = 1e-3 s). The program prints the final
 * state, one "name value" per line in the header's state order, then the
 * angular momentum about AB* in N components and its norm. With g = 0 and an
 * internal motor torque, that momentum is conserved: its drift is a check on
 * the integration that needs no second program.
 *
 * Initial state: all angles and the translation zero;
 *   u1 = 0.01, u2 = 0.5, u3 = -0.02 rad/s (carrier rates, A components),
 *   u4 = 100 rad/s (rotor's absolute rate about a2).
 */
#include "gyrostat.h"
#include "gyrostat_ode.h"

#include <math.h>
#include <stdio.h>

#define T_END 10.0
#define DT 1e-3
#define STEPS 10000  /* T_END / DT, kept an integer so t never accumulates error */

static const char *const state_names[GYROSTAT_NX] = {
    "q1", "q2", "q3", "q4", "q5", "q6", "q7",
    "u1", "u2", "u3", "u4", "u5", "u6", "u7",
};

/*
 * Angular momentum about AB* in N components (NOTES.md). The generated code
 * keeps the lumped inertias inside setup's constants, so they are recomputed
 * here from the parameters:
 *   mu = m_a m_b / (m_a + m_b)
 *   I~11 = I11 + I + mu l3^2, I~22 = I22 + mu (l1^2 + l3^2),
 *   I~33 = I33 + I + mu l1^2, I~13 = I13 - mu l1 l3
 *   h (A components) = (I~11 u1 + I~13 u3, I~22 u2 + J u4, I~13 u1 + I~33 u3)
 * and a_i = sum_j C[i][j] n_j (3-1-2 direction cosines), so H_j = sum_i h_i C[i][j].
 */
static void angular_momentum_n(const double *p, const double *x, double *H)
{
    const double m_a = p[0], m_b = p[1], I11 = p[2], I22 = p[3], I33 = p[4], I13 = p[5];
    const double I = p[6], J = p[7], l1 = p[8], l3 = p[9];
    const double mu = m_a * m_b / (m_a + m_b);
    const double t11 = I11 + I + mu * l3 * l3;
    const double t22 = I22 + mu * (l1 * l1 + l3 * l3);
    const double t33 = I33 + I + mu * l1 * l1;
    const double t13 = I13 - mu * l1 * l3;
    const double u1 = x[7], u2 = x[8], u3 = x[9], u4 = x[10];
    const double h[3] = {t11 * u1 + t13 * u3, t22 * u2 + J * u4, t13 * u1 + t33 * u3};
    const double s1 = sin(x[0]), s2 = sin(x[1]), s3 = sin(x[2]);
    const double c1 = cos(x[0]), c2 = cos(x[1]), c3 = cos(x[2]);
    const double C[3][3] = {
        {c1 * c3 - s1 * s2 * s3, s1 * c3 + c1 * s2 * s3, -c2 * s3},
        {-s1 * c2, c1 * c2, s2},
        {s1 * s2 * c3 + c1 * s3, s1 * s3 - c1 * s2 * c3, c2 * c3},
    };
    int i, j;

    for (j = 0; j < 3; ++j) {
        H[j] = 0.0;
        for (i = 0; i < 3; ++i) H[j] += h[i] * C[i][j];
    }
}

int main(void)
{
    /* m_a m_b I11 I22 I33 I13 I J l1 l3 g T, in the header's order and units. */
    const double p[GYROSTAT_NP] = {500.0, 10.0, 100.0, 80.0, 120.0, 5.0,
                                   0.05, 0.1, 0.2, -0.1, 0.0, 0.01};
    double c[GYROSTAT_NC];
    double x[GYROSTAT_NX] = {0.0};
    double H[3];
    gyrostat_stats stats;
    int code, k;

    code = gyrostat_setup(p, c);
    if (code != GYROSTAT_OK) {
        fprintf(stderr, "gyrostat_setup failed (code %d): %s\n", code, gyrostat_strerror(code));
        return 1;
    }

    x[7] = 0.01;   /* u1 */
    x[8] = 0.5;    /* u2 */
    x[9] = -0.02;  /* u3 */
    x[10] = 100.0; /* u4 */
    /* The generated classic RK4: STEPS equal steps of DT over [0, 10 s]. */
    code = gyrostat_rk4(0.0, STEPS * DT, STEPS, x, c, &stats);
    if (code != GYROSTAT_ODE_OK) {
        fprintf(stderr, "gyrostat_rk4 failed (code %d) at t = %g: %s\n", code, stats.t,
                gyrostat_ode_strerror(code));
        return 1;
    }

    for (k = 0; k < GYROSTAT_NX; ++k) printf("%s %.17g\n", state_names[k], x[k]);
    angular_momentum_n(p, x, H);
    printf("H_n1 %.17g\nH_n2 %.17g\nH_n3 %.17g\n", H[0], H[1], H[2]);
    printf("H_norm %.17g\n", sqrt(H[0] * H[0] + H[1] * H[1] + H[2] * H[2]));
    return 0;
}
